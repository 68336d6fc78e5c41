"""What the cameras see: camera models and their projection Jacobian (camera; the pinhole model with
distortion in pinhole), the support images the paper's criterion reads (support), the medial axis of
a silhouette (medial_axis), silhouettes from video and their temporal voting (segmentation), and
capsule silhouettes of a posed body (render)."""
