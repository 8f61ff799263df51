"""Scores: detection (MODA, MODP, P, R, F1, APE) and tracking (MOTA, IDF1, MT/PT/ML, FRAG)."""
