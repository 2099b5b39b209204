"""GPU figures: gsplat, the vectorised environment, several GPUs."""
