"""Matrix product states (MPS) and operators (MPO) for long open roads (issue 35)."""
