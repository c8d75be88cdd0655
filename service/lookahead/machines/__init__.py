"""Shipped machine configurations (`lookahead ... --config NAME` or `demo --machine NAME`):
`winder2` (the default two-drive winder, X and C), `winder3` (X, C and the delivery head
B, the drives fiberpath's programs command) and `winder4` (winder3 with a cross-feed Y)."""
