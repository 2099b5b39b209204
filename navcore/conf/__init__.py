"""Configuration data navcore needs, shipped inside the package: the embodiments (embodiment/*.yaml,
read by navcore.nav.embodiment and composed by the pipeline's Hydra config as the group `embodiment`
through its search path pkg://navcore.conf)."""
