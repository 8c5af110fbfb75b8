"""Shared codes of the rigid step: body kinds, contact models, and the columns of a contact
record row (stepper module doc), laid out from their names and widths in RECORD_FIELDS."""

DYNAMIC, STATIC, KINEMATIC = 0, 1, 2

#: Contact model codes by StepParams.contact name (Options.contact; stepper.step_models picks
#: the contact model by them and rejects any other code).
CONTACT_MODELS = {"impulse": 0, "linear": 1, "hunt-crossley": 2}
IMPULSE, LINEAR, HUNT_CROSSLEY = (CONTACT_MODELS[k] for k in ("impulse", "linear", "hunt-crossley"))

#: A contact record row, in order: (field, columns). Units: s, step number, body numbers, world
#: point (m), impulse on body a (N s, world), approach speed (m/s), slip and rolling speed after
#: the solve (m/s), impact flag, features of a and b, barycentric weights on b, the contact
#: point in each body's frame (m), the unit normal from b to a.
RECORD_FIELDS = (
    ("time", 1),
    ("step", 1),
    ("a", 1),
    ("b", 1),
    ("point", 3),
    ("impulse", 3),
    ("speed", 1),
    ("slip", 1),
    ("roll", 1),
    ("impact", 1),
    ("feat_a", 1),
    ("feat_b", 1),
    ("bary", 3),
    ("local_a", 3),
    ("local_b", 3),
    ("normal", 3),
)


def _record_columns() -> dict[str, int]:
    """First column of each record field."""
    columns, at = {}, 0
    for name, width in RECORD_FIELDS:
        columns[name] = at
        at += width
    columns["width"] = at
    return columns


RECORD_COLUMNS = _record_columns()
REC_TIME, REC_STEP, REC_A, REC_B = (RECORD_COLUMNS[k] for k in ("time", "step", "a", "b"))
REC_POINT, REC_IMPULSE, REC_SPEED, REC_SLIP = (
    RECORD_COLUMNS[k] for k in ("point", "impulse", "speed", "slip")
)
REC_ROLL, REC_IMPACT, REC_FEAT_A, REC_FEAT_B = (
    RECORD_COLUMNS[k] for k in ("roll", "impact", "feat_a", "feat_b")
)
REC_BARY, REC_LOCAL_A, REC_LOCAL_B, REC_NORMAL = (
    RECORD_COLUMNS[k] for k in ("bary", "local_a", "local_b", "normal")
)
REC_WIDTH = RECORD_COLUMNS["width"]
