"""Reading scenes (OBJ + MTL, View3D .vs3) and writing results (PNG, VTP, PLY, JSON, NPZ)."""
