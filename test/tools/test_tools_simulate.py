"""``simulate`` in-process: every option checked before the run, an honest settling time."""
import re

from conftest import REPO
import matplotlib.figure
import pytest

from continuum_statics.tools import simulate

ROBOT = str(REPO / 'config' / 'tendon_robot_dynamic.yaml')


def simulate_main(capsys, *args):
    """Return (exit code, stdout, stderr) of ``simulate --robot ROBOT *args``."""
    try:
        code = simulate.main(['--robot', ROBOT, *args])
    except SystemExit as exit_:  # argparse's refusal
        code = exit_.code
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize('args, reason', [
    # before: OverflowError traceback
    (['--release', '--duration', 'inf'], 'argument --duration: must be finite and > 0'),
    # before: ZeroDivisionError traceback
    (['--release', '--motor-bandwidth', '0'], 'argument --motor-bandwidth: must be finite'),
    # before: accepted silently (a negative time constant)
    (['--release', '--motor-bandwidth', '-5'], 'argument --motor-bandwidth'),
    (['--release', '--motor-bandwidth', 'nan'], 'argument --motor-bandwidth'),
    (['--release', '--max-speed', '0'], 'argument --max-speed: must be > 0'),
    (['--release', '--max-speed', '-1'], 'argument --max-speed: must be > 0'),
    # before: a FileNotFoundError traceback after the whole run
    (['--release', '--plot', '/no/such/dir/x.png'], 'no folder /no/such/dir'),
    # before: ran until killed (10^12 and 2 x 10^9 steps)
    (['--release', '--duration', '1e9'], 'is 1000000000000 steps; the limit is 200000'),
    (['--release', '--dt', '1e-9'], 'is 2000000000 steps; the limit is 200000'),
    # before: ran, the rod collapsing under 19.6 N
    (['--release', '--tip-mass', '2'], 'payload 2 kg .* beyond what the rod can carry'),
    # before: ran, the tip moved 168.5 mm where the driver would clip
    (['--step', 'cable_0', '-0.05'], r"outside the cable's length limits \[0.2700, 0.3300\]"),
    (['--step', 'cable_0', 'abc'], 'not a number'),
    (['--release', '--alpha', '-0.6'], 'alpha must be in'),
])
def test_bad_input_is_refused_before_the_run_with_the_reason(capsys, args, reason):
    code, out, err = simulate_main(capsys, *args)
    assert code == 2 and out == ''
    assert 'Traceback' not in err
    assert re.search(reason, err), err


def test_a_run_cut_short_is_not_settled_and_a_whole_one_is(capsys, tmp_path, monkeypatch):
    code, out, _ = simulate_main(capsys, '--release', '--duration', '0.2')
    # before: 'settling time 0.200 s' (the band centred on the last sample)
    assert code == 0 and 'settling time not settled within the run' in out
    titles = []
    save = matplotlib.figure.Figure.savefig

    def savefig(figure, *args, **kwargs):
        titles.append(figure.axes[0].get_title())
        return save(figure, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, 'savefig', savefig)
    path = tmp_path / 'release.png'
    code, out, _ = simulate_main(capsys, '--release', '--duration', '2', '--plot', str(path))
    assert code == 0 and 'settling time 0.66' in out  # 0.663 s before and after
    # before: no title, and nothing said where the plot went
    assert titles == ['robot tendon_robot_4c_dynamic: release from 0.506 N']
    assert 'plot: %s' % path in out and path.stat().st_size > 0
