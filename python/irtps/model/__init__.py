"""The data model: the scene, the data set and ground truth, the errors against it, the options and
the choice lists and bounds they share."""
