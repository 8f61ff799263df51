"""The projector service: 2D boxes to world cylinders."""
