"""ObjectNav goals: lifting with the oracle, shipped labels, the detector, covering views, segmenters."""
