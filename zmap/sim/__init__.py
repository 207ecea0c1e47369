"""NC cutting simulation on z-map workpieces with full history (papers 000 and 001)."""
