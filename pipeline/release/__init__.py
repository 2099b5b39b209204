"""`navarena release`: a versioned release folder from a finished data root (build.py), with its
dataset card (card.py), Croissant metadata (croissant.py), statistics (stats.py) and release notes
(notes.py). `navarena verify-release` (navarena/verify_release.py) checks a downloaded copy."""
