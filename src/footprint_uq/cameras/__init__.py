"""Camera models: each is a trio of forward projection, back-projection to the ground, Jacobian."""
