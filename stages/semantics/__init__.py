"""Semantic layer: ObjectNav goal candidates lifted from multi-view masks."""
