"""What a tracked motion looks like: plots of per-frame series (plots), the skeleton drawn on images
(drawing) and over each camera's silhouettes as videos (overlay), and a 3D replay in one HTML file
(replay)."""
