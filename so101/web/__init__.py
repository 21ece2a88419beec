"""The arm in a browser: the URDF as a scene of frames and meshes, and the node's web server."""
