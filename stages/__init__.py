"""NavArena stages: one module or small package per pipeline stage.

Each stage has a config dataclass, pure core functions (arrays in, arrays out) and one thin
``run(scene, cfg, catalog)`` that reads its inputs, calls the core and writes its outputs.
"""
