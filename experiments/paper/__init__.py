"""Support code of the paper's experiments: virtual scenes (Figs. 6-8) and Section 4 on real motion."""
