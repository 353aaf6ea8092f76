"""The least-squares family: estimators that solve the regressor's linear system ``W α ≈ τ_s``.

``observation`` builds and checks the system (stacked over trials), ``least_squares`` holds LS and
TLS and the shared ``LinearEstimator``, ``robust_ls`` RLS, ``uncertainty`` the standard deviation
of each base parameter. Nothing here searches: the family imports no search estimator
(``tests/test_layout.py``), and third-party linear estimators (``irls`` of ``idkit-robust``) build
on ``observation.stacked_system`` the same way.
"""
