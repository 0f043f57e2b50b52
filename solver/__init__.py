"""solver: intensity scan (FieldMap) -> surface map (SurfaceMap)."""
