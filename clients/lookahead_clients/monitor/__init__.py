"""`lookahead monitor`: a live web page of one or more machines on the bus.

`cli` (the subcommand), `bus_side` (zenoh subscriptions and commands), `machine_view` (the
state of one machine), `chart` (finite differences and decimation), `path_view` (the
programmed path and progress along it), `server` (HTTP + Server-Sent Events) and `static/`
(the page: plain HTML, JS and <canvas>, no external resources).
"""
