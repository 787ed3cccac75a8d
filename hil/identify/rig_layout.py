"""The independent rig's kernel layout: where each parameter and state sits in its vectors.

Apart from :mod:`hil.identify.rig` so that the rig's per-effect classes
(:mod:`hil.identify.rig_effects`) can fill the parameter vector without importing the
generator that uses them. Like the rig, it imports nothing of the fitted model.
"""

#: Parameter vector layout.
(I_K, I_DS, I_DP, I_DC, I_KS, I_JP, I_JC, I_KROD, I_CROD, I_P0, I_KC, I_KCKP, I_LOAD,
 I_PC, I_PC_EPS, I_SF_C, I_SF_S, I_SF_VS, I_SF_EPS, I_KSX, I_VSIDE, I_KAPPA, I_KPIPE, I_HALF,
 I_VISC, I_TREF, I_DRIFT, I_T0, I_KM, I_KM_RATE, I_WP, I_WS, I_TH0, I_TAU_CL, I_XLSB,
 N_P) = range(36)

#: State vector layout.
(Z_THP, Z_VP, Z_TAUS, Z_TAUM, Z_XC, Z_VC, Z_PPA, Z_PPB, Z_PCA, Z_PCB, Z_FS, N_Z) = range(12)
