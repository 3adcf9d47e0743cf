"""Position estimator (thesis 4.1): model-based KF of eq. 4.35 (model_kf), PVA KF of
eqs. 4.30-4.34 (pva), Chinniah friction estimators of eqs. 4.15-4.29 (chinniah), the
position-sensor fault detector (fault_detector) and the Estimator the node wraps (estimator)."""
