"""Scores: detection (MODA, MODP, P, R, F1, APE), tracking (MOTA, IDF1, MT/PT/ML, FRAG) and HOTA."""
