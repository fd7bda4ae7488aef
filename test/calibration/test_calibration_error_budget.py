"""The error budget: the repeatability floor, model-free baselines and their cross-validation.

Truths: synthetic runs whose tips are a known smooth function of the motor positions plus
Gaussian noise of known sigma, repeated commands whose spread is that noise, and the real v6
runs (figures of its data README and issue 21: pairs within 0.25 mm about 5-6 mm per row).
"""
from conftest import REPO
import numpy as np
import pytest

from continuum_statics.calibration.error_budget import (
    error_budget,
    folds,
    format_budget,
    pattern_groups,
    repeatability,
)
from continuum_statics.calibration.recorded_run import ColumnMap, RecordedRun, read_recorded_run

DATA = REPO / 'test' / 'data' / 'ftdcr_v6'


def smooth_tips(lengths):
    """Return a smooth (quadratic) map of 4 motor lengths (m) to a tip (m)."""
    z = (lengths - 0.2) / 0.01
    return np.column_stack([0.02 * z[:, 0] - 0.01 * z[:, 1] * z[:, 2],
                            0.015 * z[:, 1] + 0.005 * z[:, 3] ** 2,
                            0.2 - 0.003 * (z[:, 0] ** 2 + z[:, 1] ** 2)])


def synthetic_run(rng, count, sigma, patterns=12, repeats=1):
    lengths = 0.2 + 0.01 * rng.uniform(-1.0, 1.0, (count, 4))
    lengths = np.repeat(lengths, repeats, axis=0)
    tips = smooth_tips(lengths) + rng.normal(0.0, sigma, (len(lengths), 3))
    labels = tuple('rep1_pattern%d' % (i * patterns // len(lengths)) for i in range(len(lengths)))
    return RecordedRun(times=np.arange(len(lengths), dtype=float), labels=labels,
                       lengths=lengths, tips=tips, source='synthetic')


def test_the_floor_of_repeated_commands_is_their_noise():
    rng = np.random.default_rng(4)
    sigma = 1e-3
    run = synthetic_run(rng, 400, sigma, repeats=2)
    floor = repeatability(run.lengths, run.tips)
    # each pair is one command twice: |d|^2 has mean 2 * 3 sigma^2, one row's error sigma sqrt 3
    assert floor['pairs'] >= 400
    assert floor['per_row'] == pytest.approx(sigma * np.sqrt(3.0), rel=0.1)
    assert repeatability(run.lengths[::2], run.tips[::2])['pairs'] == 0  # no repeats, no floor


def test_the_baselines_choose_their_settings_inside_the_training_run():
    rng = np.random.default_rng(5)
    sigma = 2e-4
    train, held_out = synthetic_run(rng, 600, sigma), synthetic_run(rng, 200, sigma)
    budget = error_budget(train, held_out)
    polynomial = budget['baselines']['polynomial_ridge']
    assert polynomial['setting'][0] == 2 or polynomial['setting'][0] == 3  # the map's degree
    # a quadratic fitted on 600 rows predicts new rows to about the noise (sigma sqrt 3 per row)
    assert polynomial['held_out_rms'] < 1.5 * sigma * np.sqrt(3.0)
    # nearest neighbours cannot interpolate as well in 4-D from 600 rows
    assert budget['baselines']['nearest_neighbours']['held_out_rms'] > polynomial['held_out_rms']
    # the held-out run never chooses: other held-out tips, the same settings
    shuffled = RecordedRun(held_out.times, held_out.labels, held_out.lengths,
                           held_out.tips[::-1].copy(), held_out.source)
    again = error_budget(train, shuffled)
    for name in ('polynomial_ridge', 'nearest_neighbours'):
        assert again['baselines'][name]['setting'] == budget['baselines'][name]['setting']
        assert again['baselines'][name]['train_cv_rms'] == budget['baselines'][name][
            'train_cv_rms']


def test_patterns_group_repetitions_and_phases_and_folds_keep_them_whole():
    labels = ['rep1_seg1_dir90', 'rep1_seg1_dir90_hold', 'rep2_seg1_dir90',
              'rep1_tendon3_id9_pull',
              'rep1_tendon3_id9_release', 'rep1_seg2_circle']
    groups = pattern_groups(labels)
    assert groups.tolist() == [0, 0, 0, 1, 1, 2]
    fold = folds(groups, count=2)
    assert fold.tolist() == [0, 0, 0, 1, 1, 0]
    unlabelled = pattern_groups([''] * 20)
    assert unlabelled.tolist() == [i // 2 for i in range(20)]


def test_the_v6_budget_shows_the_robots_floor_and_the_model_free_baselines():
    columns = ColumnMap(cables=tuple('servo_%d_mm' % i for i in (1, 20, 23, 9, 6, 11, 24, 2, 3)),
                        kind='displacement', scale=1e-3, tip_scale=1e-3)
    straight = np.full(9, 0.25)
    train = read_recorded_run(DATA / 'train.csv', [str(i) for i in range(9)], straight, columns)
    val = read_recorded_run(DATA / 'val.csv', [str(i) for i in range(9)], straight, columns)
    errors = np.random.default_rng(6).normal(0.0, 8e-3 / np.sqrt(3.0), (len(train), 3))
    budget = error_budget(train, val, {'train': errors})
    floor = budget['repeatability']
    # issue 21: rows whose motor positions agree within 0.25 mm are about 5-6 mm apart per row
    assert 4.5e-3 < floor['train']['per_row'] < 6.5e-3 and floor['train']['pairs'] > 500
    assert 4.5e-3 < floor['held_out']['per_row'] < 7.0e-3
    # the held-out motions (all three sections at once) lie outside the training patterns:
    # model-free baselines of the motor positions do worse there than the 11 mm of the physics
    for entry in budget['baselines'].values():
        assert entry['held_out_rms'] > 11e-3
    model = budget['model']['train']
    aligned = errors - errors.mean(axis=0)
    assert model['beyond_floor'] == pytest.approx(np.sqrt(
        np.mean(np.sum(aligned ** 2, axis=1)) - floor['train']['per_row'] ** 2), rel=1e-9)
    text = format_budget(budget)
    assert 'repeatability floor' in text and 'polynomial ridge' in text
