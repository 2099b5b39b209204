"""Closed-loop evaluation: the navigation environment, metrics, agents and the evaluate stage."""
