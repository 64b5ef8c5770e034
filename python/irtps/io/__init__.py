"""Reading and writing data sets, images and meshes."""
