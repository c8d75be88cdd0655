"""Clients of the lookahead bus: segment publisher, simulated winder, recorder/replay, demo.

They speak only the wire protocol (`lookahead.protocol`) and use the independent limit
checker; they import nothing of the planner.
"""
