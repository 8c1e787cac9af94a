"""The LEAP template (derived from the LEAP URDF) and its 256 finger-truncated variants."""
