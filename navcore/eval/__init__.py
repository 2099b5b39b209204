"""The closed-loop evaluator as a library (design.md): episodes, the environment and its batched
form, the loops, metrics, agents and the agent-server protocol. It depends on navcore only; the
pipeline's `evaluate` stage, `navarena eval` and the gym env run it. The public names are
re-exported by the `navarena` package."""
