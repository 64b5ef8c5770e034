"""The data model: the scene, the data set and ground truth, the options."""
