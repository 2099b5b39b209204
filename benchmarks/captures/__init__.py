"""Real captures: the pipeline on trained scenes and the labelled scan, screening, render checks."""
