"""Contact identity across calls (Engine(history=True)): every call's contacts carry age (consecutive
earlier calls of this engine that had the pair) and previous_row (the pair's row in the previous call's
contacts, -1 when new), checked against an oracle built from the exact pair lists of the calls."""
import numpy as np
import pytest

import contactgrid
from conftest import history_oracle, random_spheres, sphere_pairs

CALLS = 3


def moving_bodies(n, seed, calls=CALLS, step=0.2):
    """Positions of `calls` calls: each moves every body by up to `step` per axis (pairs break, form
    and persist), and the radii."""
    p, r = random_spheres(n, seed, contacts_per_body=3.0)
    rng = np.random.default_rng(seed + 1)
    frames = [p]
    for _ in range(calls - 1):
        frames.append(frames[-1] + rng.uniform(-step, step, size=p.shape))
    return frames, r


def check_history(results, frames, r):
    """Each result against the exact pairs of its frame and the history oracle of the frames before."""
    history = []
    ages = []
    for contacts, p in zip(results, frames):
        pairs = sphere_pairs(p, r)
        np.testing.assert_array_equal(contacts.id_a, pairs[0])
        np.testing.assert_array_equal(contacts.id_b, pairs[1])
        age, previous_row = history_oracle(history, pairs)
        assert contacts.history and contacts.age.dtype == np.int64 and contacts.previous_row.dtype == np.int64
        np.testing.assert_array_equal(contacts.age, age)
        np.testing.assert_array_equal(contacts.previous_row, previous_row)
        history.append(pairs)
        ages.append(age)
    # The scene exercises every case: pairs new in the last call, pairs kept since the first, pairs
    # that broke (rows of the second call missing from the third).
    last = ages[-1]
    assert (last == 0).any() and (last == CALLS - 1).any() and (last == 1).any()
    kept = results[-1].previous_row[results[-1].previous_row >= 0]
    assert len(set(kept.tolist())) < len(results[-2])


@pytest.mark.parametrize("precision", ["fp64", "fp32"])
def test_age_and_previous_row_over_three_calls(precision):
    frames, r = moving_bodies(3000, 61)
    engine = contactgrid.Engine(backend="cpu", precision=precision, history=True)
    results = [engine.detect(p, r) for p in frames]
    if precision == "fp64":
        check_history(results, frames, r)
    else:  # fp32 contacts may differ from the float64 oracle at the touching boundary: check against its own pairs
        history = []
        for c in results:
            pairs = (np.asarray(c.id_a), np.asarray(c.id_b))
            age, previous_row = history_oracle(history, pairs)
            np.testing.assert_array_equal(c.age, age)
            np.testing.assert_array_equal(c.previous_row, previous_row)
            history.append(pairs)
    c = results[-1]
    assert c.keys()[-2:] == ["age", "previous_row"] and "age" in c and c["age"] is not None
    assert c.age.base is c and c["previous_row"].base is c  # no copy: views of the engine's result
    # previous_row indexes the previous result: the same pair there
    prev = results[-2]
    rows = c.previous_row >= 0
    np.testing.assert_array_equal(prev.id_a[c.previous_row[rows]], c.id_a[rows])
    np.testing.assert_array_equal(prev.id_b[c.previous_row[rows]], c.id_b[rows])
    np.testing.assert_array_equal(prev.age[c.previous_row[rows]] + 1, c.age[rows])


def test_resident_steps_carry_history_as_detect_does():
    frames, r = moving_bodies(3000, 62)
    engine = contactgrid.Engine(backend="cpu", precision="fp64", history=True, skin=0.3)
    engine.set_resident(frames[0], r)
    results = [engine.detect_resident()]
    for p in frames[1:]:
        engine.write_resident(0, p, r)
        results.append(engine.detect_resident())
    check_history(results, frames, r)
    assert engine.stats["candidate_reuses"] + engine.stats["candidate_builds"] >= 1
    by_detect = contactgrid.Engine(backend="cpu", precision="fp64", history=True)
    for p, c in zip(frames, results):
        d = by_detect.detect(p, r)
        assert d.keys() == c.keys()
        for name in d.keys():
            np.testing.assert_array_equal(d[name], c[name], err_msg=name)


def test_reset_history_makes_every_pair_new():
    frames, r = moving_bodies(2000, 63)
    engine = contactgrid.Engine(backend="cpu", precision="fp64", history=True)
    engine.reset_history()  # before any call: nothing to forget
    engine.detect(frames[0], r)
    second = engine.detect(frames[1], r)
    assert (second.age > 0).any() and (second.previous_row >= 0).any()
    engine.reset_history()
    third = engine.detect(frames[2], r)
    assert len(third) > 0
    np.testing.assert_array_equal(third.age, np.zeros(len(third), dtype=np.int64))
    np.testing.assert_array_equal(third.previous_row, np.full(len(third), -1, dtype=np.int64))
    fourth = engine.detect(frames[2], r)  # the history goes on from the call after the reset
    np.testing.assert_array_equal(fourth.age, np.ones(len(fourth), dtype=np.int64))
    np.testing.assert_array_equal(fourth.previous_row, np.arange(len(fourth)))


def test_history_fields_need_history_true():
    p, r = random_spheres(500, 64)
    for contacts in (contactgrid.detect(p, r, backend="cpu"), contactgrid.Engine(backend="cpu").detect(p, r)):
        assert not contacts.history and "age" not in contacts and "previous_row" not in contacts.keys()
        with pytest.raises(KeyError, match=r"history=True"):
            contacts["age"]
        with pytest.raises(AttributeError, match="previous_row"):
            contacts.previous_row
    full = contactgrid.Engine(backend="cpu", fields="full", history=True).detect(p, r)
    assert full.keys() == ["id_a", "id_b", "position_on_a", "position_on_b", "normal_on_b", "distance",
                           "local_point_a", "local_point_b", "lateral_friction_dir1", "lateral_friction_dir2",
                           "age", "previous_row"]
    empty = contactgrid.Engine(backend="cpu", history=True).detect(np.zeros((0, 3)), np.zeros(0))
    assert len(empty) == 0 and empty.history and empty.age.shape == (0,)


def test_history_fields_in_contact_files(tmp_path, cli):
    h5py = pytest.importorskip("h5py")
    frames, r = moving_bodies(2000, 65)
    engine = contactgrid.Engine(backend="cpu", precision="fp64", history=True)
    engine.detect(frames[0], r)
    contacts = engine.detect(frames[1], r)
    contactgrid.write_contacts(tmp_path / "c.h5", contacts)
    with h5py.File(tmp_path / "c.h5", "r") as f:
        np.testing.assert_array_equal(f["/contacts/age"][:], contacts.age)
        np.testing.assert_array_equal(f["/contacts/previous_row"][:], contacts.previous_row)
        assert f["/contacts/age"].dtype == np.int64
    back = contactgrid.read_contacts(tmp_path / "c.h5")
    assert back.history and back.keys() == contacts.keys()
    for name in contacts.keys():
        np.testing.assert_array_equal(back[name], contacts[name], err_msg=name)
    contactgrid.write_contacts(tmp_path / "d.h5", back)  # what was read writes the same file
    assert "IDENTICAL" in cli("compare", tmp_path / "c.h5", tmp_path / "d.h5").stdout
    plain = contactgrid.read_contacts(tmp_path / "c.h5")
    contactgrid.write_contacts(tmp_path / "e.h5", contactgrid.detect(frames[1], r, backend="cpu", precision="fp64"))
    assert not contactgrid.read_contacts(tmp_path / "e.h5").history and plain.history
    with h5py.File(tmp_path / "e.h5", "r") as f:
        assert "age" not in f["contacts"]
