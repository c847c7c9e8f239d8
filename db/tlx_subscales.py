"""The six NASA-TLX subscales, the rating columns of `tlx_responses` (`db.models.tlx`),
apart from the models so that a plain-SQL reader names them without SQLAlchemy."""

TLX_SUBSCALES = (
    "mental",
    "physical",
    "temporal",
    "performance",
    "effort",
    "frustration",
)
