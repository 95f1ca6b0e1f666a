"""The point-cloud encoders (pure torch): the CORN patch transformer and PointNet, their patches,
input normalisation, files and contact metrics."""
