"""NavArena for its users: what you run on a finished dataset, without the pipeline.

- navarena.observations: PyTorch datasets rendering egocentric RGB-D at the stored expert poses;
- navarena.lerobot: a split as a LeRobot dataset (`navarena export-lerobot`);
- navarena.render_episodes: MP4 videos of chosen episodes and a per-scene HTML report
  (`navarena render-episodes`).
They read a data root through the catalog's datasets (navcore.io.catalog) and render with
navcore.render; they import nothing of the orchestration (pipeline) or of the stages (an import
contract holds it). The NavArena / Habitat / ROS exports are the export stage's (stages.export).
"""
