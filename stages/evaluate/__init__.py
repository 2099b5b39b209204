"""The `evaluate` stage: an agent over the stored episodes of each scene of a run, and the run's
reports. The environment, metrics, agents and agent-server protocol it schedules are the library's
(navcore.eval)."""
