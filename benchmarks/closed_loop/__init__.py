"""Closed-loop evaluation: metrics, blocked-move dynamics, observations for training."""
