"""blendsim-ray: `blendsim bake` of many scenes as Ray tasks (docs/cluster.md)."""

__version__ = "0.1.0"
