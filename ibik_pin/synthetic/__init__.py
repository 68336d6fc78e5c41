"""Synthetic data with a known truth: real motion capture posed on the model (mocap), camera rigs
(rig), rendered silhouettes (silhouettes) and their defects (defects), data sets written as
`ibik track` reads them (dataset), and the paper's planar chain (planar)."""
