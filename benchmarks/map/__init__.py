"""The spatial layer: costmaps against mesh references, alignment, voxelization."""
