"""ssd_jax: self-supervised point set local descriptors for LiDAR registration, in JAX."""

__version__ = '0.1.0'
