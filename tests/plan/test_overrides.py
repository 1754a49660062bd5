"""Plan-file text with keys set or removed (`plan.overrides.with_keys`), checked by reading the
result back with tomllib."""

import tomllib

import pytest

from gyrostand.plan.overrides import with_keys

TEXT = """# a plan
[settle]  # when to observe
method = "estimate"   # the model
expected_se_deg = 0.015
hold_s = 1800.0

[bus]
seed = 1
"""


def test_keys_are_set_added_and_removed_and_the_rest_kept() -> None:
    out = with_keys(
        TEXT,
        {
            "settle": {"method": "band", "expected_se_deg": None, "band_deg": 0.02},
            "bus.simulator.compass": {"t_s": 0.9},
        },
    )
    doc = tomllib.loads(out)
    assert doc["settle"] == {"method": "band", "band_deg": 0.02, "hold_s": 1800.0}
    assert doc["bus"] == {"seed": 1, "simulator": {"compass": {"t_s": 0.9}}}
    assert out.startswith("# a plan\n[settle]  # when to observe\n")
    assert with_keys(TEXT, {"settle": {"absent_key": None}}) == TEXT


def test_a_key_that_cannot_be_set_is_an_error() -> None:
    inline = 'settle = { method = "band" }\n'
    with pytest.raises(ValueError, match=r"is no TOML: Cannot declare \(.settle.,\) twice"):
        with_keys(inline, {"settle": {"method": "estimate"}})
