"""Processes of the tools (demo, benches, soak) and the tests: ROS environment, CPU time, stop."""
import os
import random
import signal
import subprocess

from continuum_statics.config_paths import share_dir


def ros_environment():
    """Loopback discovery, a domain of its own and the quick-discovery profile, unless set."""
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(100, 199)))
    os.environ.setdefault('FASTDDS_DEFAULT_PROFILES_FILE',
                          str(share_dir() / 'config' / 'fastdds_fast_discovery.xml'))


def cpu_seconds(pid):
    """User + system CPU time of a process, s (Linux /proc)."""
    with open('/proc/%d/stat' % pid) as stat:
        fields = stat.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def stop(process, timeout=15.0):
    """SIGINT, then kill if it does not exit; return the exit code."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    return process.returncode
