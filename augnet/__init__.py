"""augnet: track-side GNSS augmentation network for satellite-based train control."""

__version__ = "0.1.0"
