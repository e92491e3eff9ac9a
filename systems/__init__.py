"""Drake LeafSystems, each beside the pure-numpy core it wraps."""
