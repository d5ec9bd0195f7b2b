"""Front ends other than G-code: B-spline/NURBS curve data (DXF, STL and point files come later)."""
