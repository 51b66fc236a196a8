"""
Maps and their topological index (paper section III).

Map files, occupancy grids from scans, GVD topology, ray casting, the index (``build_index``).
"""
