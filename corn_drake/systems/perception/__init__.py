"""The camera side: RGB-D cameras and their clouds, the object's segmentation, ICP tracking."""
