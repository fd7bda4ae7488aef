"""config/continuum_robot.rviz and the launch file's ``rviz`` argument (no rviz2 here)."""
import ast

from conftest import REPO
import yaml

from continuum_statics import load_robot

RVIZ = REPO / 'config' / 'continuum_robot.rviz'
LAUNCH = REPO / 'launch' / 'continuum_robot.launch.py'


def displays():
    config = yaml.safe_load(RVIZ.read_text())['Visualization Manager']
    return config, {d['Class']: d for d in config['Displays']}


def test_rviz_config_shows_the_statics_outputs_in_the_base_frame():
    config, by_class = displays()
    frames = {load_robot(REPO / 'config' / name).base_frame_id
              for name in ('tendon_robot.yaml', 'jones2009_nitinol_rod.yaml')}
    assert frames == {config['Global Options']['Fixed Frame']}
    expected = {'rviz_default_plugins/Path': 'backbone', 'rviz_default_plugins/Pose': 'tip_pose',
                'rviz_default_plugins/MarkerArray': 'backbone_markers'}
    for plugin, topic in expected.items():
        display = by_class[plugin]
        assert display['Enabled'] and display['Topic']['Value'] == topic
        # Published latched (reliable, transient local): the display must ask for the same.
        assert display['Topic']['Durability Policy'] == 'Transient Local'
        assert display['Topic']['Reliability Policy'] == 'Reliable'


def test_launch_file_starts_rviz2_with_the_config_on_request():
    text = LAUNCH.read_text()
    tree = ast.parse(text)
    assert "DeclareLaunchArgument('rviz', default_value='false'" in text
    assert "IfCondition(LaunchConfiguration('rviz'))" in text
    constants = [ast.literal_eval(n.value) for n in ast.walk(tree) if isinstance(n, ast.Assign)
                 and any(getattr(t, 'id', '') == 'CONFIG_FILES' for t in n.targets)]
    assert 'continuum_robot.rviz' in constants[0]
    assert "executable='rviz2'" in text and "'-d'" in text
    assert "glob('config/*.rviz')" in (REPO / 'setup.py').read_text()


def test_rviz_config_shows_the_tf_frames():
    _, by_class = displays()
    display = by_class['rviz_default_plugins/TF']
    assert display['Enabled'] and display['Show Axes'] and display['Show Names']
