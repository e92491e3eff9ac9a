"""Drake LeafSystems, each beside the pure-numpy core it wraps, in capability wings.

The generic core (contact/, c3/, learning/) imports only itself; the task wings
(perception/, franka/, rolling/) may import the core and models/. Nothing here imports
diagrams/, scenarios/ or tools/ (tests/test_layering.py keeps this true)."""
