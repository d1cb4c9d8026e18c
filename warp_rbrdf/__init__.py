"""warp-rbrdf renderer: NVIDIA Warp kernels (CPU device) for measured and rational BRDFs."""
