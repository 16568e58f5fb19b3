import numpy as np
import pytest

from haulprofile.analysis.vecto import CycleFileError, read_vdri, vdri_problems, write_vdri


@pytest.mark.parametrize("name", ["LongHaul", "RegionalDelivery", "UrbanDelivery"])
def test_real_vecto_cycles_round_trip(data_dir, tmp_path, name):
    cycle = read_vdri(data_dir / "vecto-cycles" / f"{name}.vdri")
    assert cycle["distance_m"].is_monotonic_increasing
    assert (cycle.loc[cycle["stop_time_s"] > 0, "target_speed_mps"] == 0).all()
    back = read_vdri(write_vdri(cycle, tmp_path / "c.vdri"))
    np.testing.assert_allclose(back.to_numpy(), cycle.to_numpy(), atol=1e-3)


def test_the_real_vecto_cycles_meet_the_rules_the_export_is_checked_against(data_dir):
    cycles = sorted((data_dir / "vecto-cycles").glob("*.vdri"))
    assert len(cycles) == 10
    assert {path.name: vdri_problems(path) for path in cycles} == {path.name: [] for path in cycles}


def test_bad_cycle(tmp_path):
    path = tmp_path / "bad.vdri"
    path.write_text("<s>,<v>\n0,1\n")
    with pytest.raises(CycleFileError, match="missing column"):
        read_vdri(path)
