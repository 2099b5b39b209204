"""The episode dataset: episodes, their checks and throughput, views, storage."""
