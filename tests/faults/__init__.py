"""Faults and hostile input: injected faults, fuzzed readers and frames."""
