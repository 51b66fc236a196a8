"""Maps and their topological index (paper section III): map files, GVD topology, ray casting, index."""
