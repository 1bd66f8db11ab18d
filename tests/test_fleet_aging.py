"""The pack aging law (uam_studio.fleet.aging): its shape over the whole documented range, a pack's
health as it ages, and the fitted numbers against the CMU lives (where the dataset is found)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uam_studio.errors import InputError
from uam_studio.fleet import AGING_LAW, END_OF_LIFE_FRACTION, AgingLaw, PackHealth


@settings(max_examples=60, deadline=None)
@given(a=st.floats(1e-5, 0.05), b=st.floats(0.1, 2.0), ea=st.floats(-5000, 5000), k=st.floats(0, 0.05),
       temp=st.floats(-20, 60), e1=st.floats(0, 5000), de=st.floats(0, 5000))
def test_the_law_fades_capacity_and_grows_resistance_monotonically(a, b, ea, k, temp, e1, de):
    law = AgingLaw(a, b, ea, k)
    c1, c2 = law.capacity_fraction(e1, temp), law.capacity_fraction(e1 + de, temp)
    assert 0.0 <= c2 <= c1 <= 1.0
    assert law.capacity_fraction(0.0, temp) == 1.0
    assert 1.0 <= law.resistance_ratio(e1) <= law.resistance_ratio(e1 + de)
    n = law.cycles_to(END_OF_LIFE_FRACTION, temp)
    if n < 1e5:  # the inverse: the capacity reaches 80% after cycles_to(0.8) cycles
        assert law.capacity_fraction(n, temp) == pytest.approx(END_OF_LIFE_FRACTION, abs=1e-6)


def test_a_pack_ages_with_the_charge_it_delivers_and_retires_at_80_percent():
    pack = PackHealth(q_max0=7600.0, r0_0=0.117)
    assert (pack.q_max, pack.r0, pack.retired) == (7600.0, 0.117, False)
    flown = pack.after(2000.0).after(3000.0)
    assert flown.delivered_c == 5000.0 and flown.q_max < 7600.0 and flown.r0 > 0.117
    end = pack.after(7600.0 * AGING_LAW.cycles_to(END_OF_LIFE_FRACTION) * 1.01)
    assert end.retired and end.q_max < 0.8 * 7600.0
    assert not pack.after(7600.0 * AGING_LAW.cycles_to(END_OF_LIFE_FRACTION) * 0.99).retired
    # hot packs fade faster than cool ones under the fitted law (its activation term is positive)
    assert PackHealth(7600.0, 0.117, 7600.0 * 200, temperature_c=35.0).q_max < \
        PackHealth(7600.0, 0.117, 7600.0 * 200, temperature_c=20.0).q_max


@pytest.mark.parametrize("kwargs, field", [({"charge_c": -1.0}, "charge_c"), ({"charge_c": float("nan")}, "charge_c")])
def test_bad_charge_names_the_field(kwargs, field):
    with pytest.raises(InputError, match=f"^{field}: "):
        PackHealth(7600.0, 0.117).after(**kwargs)


def test_bad_temperature_and_fraction_name_the_field():
    with pytest.raises(InputError, match="^temperature_c: "):
        AGING_LAW.capacity_fraction(100.0, temperature_c=200.0)
    with pytest.raises(InputError, match="^fraction: "):
        AGING_LAW.cycles_to(1.5)


# --------------------------------------------------------------------------- against the CMU lives


@pytest.fixture(scope="module")
def lives():
    from uam_studio.battery.real.cmu_data import LIFE_FILES, data_folder
    from uam_studio.fleet import life_points

    try:
        data_folder(needs=LIFE_FILES[0])  # the four lives, not the sample's one
    except InputError as err:
        pytest.skip(f"the CMU eVTOL dataset is not found ($UAM_STUDIO_CMU_DATA): {err}")
    return life_points()


def test_the_bundled_law_is_the_fit_to_the_four_lives(lives):
    from uam_studio.fleet import fit_aging_law

    law = fit_aging_law(lives)
    for name in ("a", "b", "ea_k", "k_r"):
        assert getattr(law, name) == pytest.approx(getattr(AGING_LAW, name), rel=1e-4), name
    assert [lf.cell for lf in lives] == ["VAH07", "VAH09", "VAH27", "VAH30"]
    assert all(np.all(np.diff(lf.efc) >= 0) and lf.efc[0] == 0.0 for lf in lives)
    # in-sample: the law holds every life's capacity within 0.12 Ah RMS (about 4% of 3 Ah)
    for lf in lives:
        err = lf.capacity_ah[0] * law.capacity_fraction(lf.efc, lf.temperature_c) - lf.capacity_ah
        assert np.sqrt(np.mean(err ** 2)) < 0.12, lf.cell


def test_held_out_cells_at_the_others_temperatures_are_within_0_1_ah(lives):
    """Leave one cell out: the three lives near 25-30 C are predicted within 0.1 Ah RMS by a law that never
    read them; VAH30 (39 C, hotter than any other life) is the worst, its temperature term extrapolated
    (0.27 Ah RMS, benchmarks/RESULTS.md): held to 0.3 Ah so that a worse law fails here."""
    from uam_studio.fleet import leave_one_cell_out

    rows = {r["cell"]: r for r in leave_one_cell_out(lives)}
    for cell in ("VAH07", "VAH09", "VAH27"):
        assert rows[cell]["rms_ah"] < 0.1, rows[cell]
    assert rows["VAH30"]["rms_ah"] < 0.3, rows["VAH30"]
