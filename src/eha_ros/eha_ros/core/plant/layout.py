"""Index layout of the flat arrays shared by the compiled kernels: an index is its name's place
in its group's tuple (unpacked from the range of the group's length, which checks the count).

P_*: parameter vector (each entry's value: parameters.PACKED); S_*: state; C_*: offsets in a
channel block (channel c starts at S_CH + c * NCH); U_*: per-tick inputs incl. fault effects;
M_*: measurement.
"""

NPAR = 64
(P_H, P_THETA, P_NEWTON_N, P_NEWTON_TOL, P_DRIVE_EVERY,
 P_BETA, P_AP, P_VD, P_MP, P_CC, P_XSTOP, P_KSTOP, P_CSTOP,
 P_FRIC, P_FC, P_FS, P_VS, P_MU,
 P_DP, P_CP, P_CR, P_LEAK_TABLE,
 P_DQ, P_R, P_L, P_KT, P_KE, P_J, P_BEQ, P_NP, P_LD, P_LQ, P_LAMBDA,
 P_TD, P_KPI, P_KII, P_KPW, P_KIW, P_LPW, P_VMAX, P_IMAX, P_WMAX, P_EXP_RL, P_EXP_LP,
 P_ACC_V0, P_ACC_P0, P_PATM,
 P_CHECK_K, P_CHECK_CRACK, P_RELIEF_CRACK, P_RELIEF_K, P_ONOFF_RATE, P_BYPASS_RATE, P_BYPASS_K,
 P_X_SIGMA, P_GM_SIGMA, P_GM_A, P_X_RES, P_W_SIGMA, P_I_SIGMA, P_PR_SIGMA, P_NOISE_ON,
 P_THETA_STIFF, P_VALVE_BAND) = range(NPAR)

S_CH = 14       # the scalar states, then the channel blocks
(S_X, S_V, S_PA, S_PB, S_VOIL, S_PACC, S_FF, S_FB, S_QREL, S_GM,
 S_NIT,                  # Newton iterations, running count (diagnostic)
 S_DPA, S_DPB, S_DV) = range(S_CH)     # last sub-step increments: Newton predictor
NCH = 11
(C_W, C_I, C_ID, C_IIQ, C_IID, C_IW, C_IF, C_FV, C_VQ, C_VD, C_TQ) = range(NCH)
NSTATE = S_CH + 2 * NCH

NIN = 18                # U_FP*: chamber A's pressure sensor, then B's (bias, stuck)
(U_WREF, U_FL, U_EN0, U_EN1, U_VT0, U_VT1, U_BT, U_FAIL0, U_FAIL1, U_LEAK0, U_LEAK1,
 U_FX_SIGMA, U_FX_BIAS, U_FX_STUCK, U_FPA_BIAS, U_FPA_STUCK, U_FPB_BIAS, U_FPB_STUCK) = range(NIN)

NM = 7
(M_X, M_W0, M_W1, M_I0, M_I1, M_PA, M_PB) = range(NM)
NNOISE = 9  # normal draws per tick
