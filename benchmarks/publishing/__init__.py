"""The release: building and verifying it."""
