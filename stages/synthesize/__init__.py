"""Procedural indoor scenes as 3D Gaussians, with ground truth (mesh, labels, transform)."""
