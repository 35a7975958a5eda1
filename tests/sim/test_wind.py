"""Wind: exact Ornstein-Uhlenbeck gusts, clipping and its reported fraction, seeding, shared field."""

import numpy as np
import pytest
from scipy.special import erfc

from mpcform.errors import ValidationError
from mpcform.sim.wind import Wind, WindField


def series(wind, n=1, seed=0, h=0.05, steps=20000):
    return WindField(wind, n, np.random.SeedSequence(seed)).sample_grid(h, steps)


def test_gusts_have_the_stationary_std_and_correlation_at_any_step():
    for h in (0.01, 0.5):
        w = series(
            Wind([1.0, -2.0], gust_std_mps=0.5, gust_time_s=2.0, gust_bound_mps=np.inf), n=50, h=h, steps=4000
        )
        g = w - np.array([1.0, -2.0])
        assert g.std() == pytest.approx(0.5, rel=0.03)
        corr = np.mean(g[1:] * g[:-1]) / np.mean(g * g)
        assert corr == pytest.approx(np.exp(-h / 2.0), abs=0.02)


def test_no_gust_is_the_mean_exactly():
    w = series(Wind([1.0, 0.5, 0.0]), n=3, steps=10)
    assert np.all(w == np.array([1.0, 0.5, 0.0]))


def test_clip_fraction_matches_the_gaussian_tail():
    for k in (0.5, 1.0, 3.0):
        field = WindField(Wind([0.0, 0.0], gust_std_mps=1.0, gust_time_s=0.05, gust_bound_mps=k), 20, 3)
        w = field.sample_grid(0.1, 5000)
        assert np.abs(w).max() <= k
        assert field.clip_fraction == pytest.approx(erfc(k / np.sqrt(2)), abs=0.01)
    assert Wind([0.0, 0.0], gust_std_mps=1.0).gust_bound_mps.tolist() == [3.0, 3.0]
    unclipped = WindField(Wind([0.0, 0.0], gust_std_mps=1.0, gust_bound_mps=np.inf), 5, 0)
    unclipped.sample_grid(0.1, 1000)
    assert unclipped.clip_fraction == 0.0


def test_per_axis_bound():
    wind = Wind([0.0, 0.0, 0.0], gust_std_mps=1.0, gust_time_s=0.1, gust_bound_mps=[0.2, 1.0, np.inf])
    w = series(wind, n=4, steps=2000)
    assert np.abs(w[..., 0]).max() == pytest.approx(0.2)
    assert np.abs(w[..., 1]).max() == pytest.approx(1.0)
    assert np.abs(w[..., 2]).max() > 2.0
    assert wind.speed_bound_mps().tolist() == [0.2, 1.0, np.inf]


def test_streams_are_deterministic_per_seed():
    wind = Wind([1.0, 0.0], gust_std_mps=0.5)
    assert np.array_equal(series(wind, 3, seed=5, steps=100), series(wind, 3, seed=5, steps=100))
    assert not np.array_equal(series(wind, 3, seed=5, steps=100), series(wind, 3, seed=6, steps=100))


def test_shared_field_gives_every_drone_the_same_gust():
    shared = series(Wind([0.0, 0.0], gust_std_mps=1.0, gust_field="shared"), n=4, steps=50)
    assert np.all(shared == shared[:, :1])
    own = series(Wind([0.0, 0.0], gust_std_mps=1.0), n=4, steps=50)
    assert not np.allclose(own[:, 0], own[:, 1])


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"mean_mps": [1.0]}, "wind.mean"),
        ({"mean_mps": [0.0, 0.0], "gust_std_mps": -1.0}, "wind.gust_std"),
        ({"mean_mps": [0.0, 0.0], "gust_time_s": 0.0}, "wind.gust_time"),
        ({"mean_mps": [0.0, 0.0], "gust_bound_mps": -1.0}, "wind.gust_bound"),
        ({"mean_mps": [0.0, 0.0], "gust_bound_mps": [1.0, 2.0, 3.0]}, "wind.gust_bound"),
        ({"mean_mps": [0.0, 0.0], "gust_field": "global"}, "wind.gust_field"),
    ],
)
def test_bad_wind_is_refused(kwargs, field):
    with pytest.raises(ValidationError, match=field):
        Wind(**kwargs)
