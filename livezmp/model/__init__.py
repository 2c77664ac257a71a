"""Body models and the files that make them: BVH skeletons, URDF robots + joint CSVs, segments and anthropometry."""
