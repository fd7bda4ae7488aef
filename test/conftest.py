"""Test-session ROS settings: loopback-only discovery, a domain per run, quick discovery.

Set before any test imports rclpy, and inherited by every subprocess the tests start, so a run
never hears another run (or a demo) on the same machine.
"""
import os
from pathlib import Path
import random

REPO = Path(__file__).resolve().parents[1]

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(10, 99)))
os.environ.setdefault(
    'FASTDDS_DEFAULT_PROFILES_FILE', str(REPO / 'config' / 'fastdds_fast_discovery.xml'))
