"""Learned baselines: the policies NavArena trains on its own episodes (navarena train), their
networks, checkpoints and the in-process agents that run them (registry names such as
`pointnav_bc`). Design notes: navcore/baselines/design.md."""
