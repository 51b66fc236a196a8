"""Maps and their topological index (paper section III): map files, occupancy grids from scans,
GVD topology, ray casting, the index (``build_index``)."""
