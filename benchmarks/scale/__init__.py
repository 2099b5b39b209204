"""Scale: the 2,000-scene run, storage per scene, the CPU renderer."""
