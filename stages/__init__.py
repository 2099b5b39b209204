"""NavArena stages: one package per stage of the graph (pipeline/graph.py), named as the stage.

Each has a config dataclass, pure core functions (arrays in, arrays out) and one thin
``stage.py:run(scene, cfg, catalog)`` that loads its inputs through ``catalog.dataset(...)``, calls
the core and saves its outputs the same way. A stage imports navcore (the shared domain) and its
own modules only: never another stage, never the pipeline.
"""
