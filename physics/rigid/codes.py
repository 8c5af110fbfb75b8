"""Shared codes of the rigid step: body kinds, contact models, the slots of the step parameter
vector (world.StepParams.vector) and the columns of a contact record row (stepper module doc)."""

DYNAMIC, STATIC, KINEMATIC = 0, 1, 2
IMPULSE, LINEAR, HUNT_CROSSLEY = 0, 1, 2
REC_TIME, REC_STEP, REC_A, REC_B, REC_POINT, REC_IMPULSE, REC_SPEED, REC_SLIP = 0, 1, 2, 3, 4, 7, 10, 11
REC_ROLL, REC_IMPACT, REC_FEAT_A, REC_FEAT_B, REC_BARY, REC_LOCAL_A, REC_LOCAL_B = 12, 13, 14, 15, 16, 19, 22
REC_NORMAL = 25
REC_WIDTH = 28
P_GX, P_GY, P_GZ, P_SLOP, P_BOUNCE, P_BETA, P_ITER, P_TOL = range(8)
P_METHOD, P_ADAPT_TOL, P_MODEL, P_K, P_C, P_EXP, P_MAX_EVENTS, P_VEPS = range(8, 16)
N_PARAMS = 16
