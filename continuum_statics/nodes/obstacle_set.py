"""The obstacles a node solves with: the robot file's and the ``obstacles`` topic's (no ROS).

Merge rule (doc/nodes.md, "Obstacles and contacts"; the Obstacles message's comment): a
message's obstacles add to the robot file's; a name given again replaces the obstacle of that
name, the robot file's or an earlier message's; a message without names clears every obstacle
the topic added (the robot file's stay, also one a topic obstacle had replaced).

Frames: a topic obstacle in the base frame (``header.frame_id`` empty or the robot's base frame)
is used as it is; one in another frame is mapped into the base frame through the newest
transforms of /tf and /tf_static (:class:`FrameTree`: the latest transform of each child frame,
composed along the tree up to the frames' common ancestor; stamps are not interpolated, so an
obstacle moves with the newest transform of its frame). One whose frame has no chain to the base
frame is left out, by name, until a transform completes the chain. A name replaced by such an
obstacle is left out too: the set never holds an obstacle where its sender no longer says it is.
"""
import numpy as np

#: Longest chain of frames followed up the tree (a loop in the transforms ends there).
MAX_DEPTH = 64


def frame_name(frame_id):
    """Return a frame id as tf2 keys it: without a leading slash ('' for None)."""
    return (frame_id or '').lstrip('/')


class FrameTree:
    """The newest transform of each child frame (/tf and /tf_static) and chains between frames.

    A transform maps child coordinates into its parent's: ``x_parent = R x_child + t``.
    """

    def __init__(self):
        self._parents = {}  # child -> (parent, R (3, 3), t (3,))

    def __len__(self):
        return len(self._parents)

    def set(self, parent, child, rotation, translation):
        """Keep the transform of ``child`` (the newest replaces the older); return True if new.

        Non-finite or self-parented transforms are ignored (False).
        """
        parent, child = frame_name(parent), frame_name(child)
        rotation = np.asarray(rotation, dtype=float)
        translation = np.asarray(translation, dtype=float)
        if not parent or not child or parent == child or not (
                np.all(np.isfinite(rotation)) and np.all(np.isfinite(translation))):
            return False
        old = self._parents.get(child)
        if old is not None and old[0] == parent and np.array_equal(old[1], rotation) and \
                np.array_equal(old[2], translation):
            return False
        self._parents[child] = (parent, rotation, translation)
        return True

    def clear(self):
        """Forget every transform."""
        self._parents.clear()

    def _ancestors(self, frame):
        """Return {ancestor: (R, t) of frame in it} and the ancestors in order, frame first."""
        rotation, translation = np.eye(3), np.zeros(3)
        found, order = {frame: (rotation, translation)}, [frame]
        while frame in self._parents and len(order) <= MAX_DEPTH:
            parent, r, t = self._parents[frame]
            if parent in found:  # a loop
                break
            rotation, translation = r @ rotation, r @ translation + t
            found[parent] = (rotation, translation)
            order.append(parent)
            frame = parent
        return found, order

    def lookup(self, frame, target):
        """Return (R, t) mapping ``frame`` coordinates into ``target``'s, or None (no chain)."""
        frame, target = frame_name(frame), frame_name(target)
        if frame == target:
            return np.eye(3), np.zeros(3)
        up, order = self._ancestors(frame)
        down, _ = self._ancestors(target)
        for common in order:
            if common in down:
                r_frame, t_frame = up[common]
                r_target, t_target = down[common]
                return r_target.T @ r_frame, r_target.T @ (t_frame - t_target)
        return None


def same_obstacles(a, b):
    """Return True when two obstacle tuples hold the same obstacles, poses and order."""
    return len(a) == len(b) and all(_key(x) == _key(y) for x, y in zip(a, b))


def _key(obstacle):
    return (obstacle.name, obstacle.kind, tuple(obstacle.size), obstacle.frame_id,
            np.asarray(obstacle.position, dtype=float).tobytes(),
            np.asarray(obstacle.rotation, dtype=float).tobytes())


class ObstacleSet:
    """The robot file's obstacles and the topic's, merged into the base frame.

    :param file_obstacles: the robot file's (base frame, ``robot.obstacles``)
    :param base_frame_id: the robot's base frame
    """

    def __init__(self, file_obstacles, base_frame_id):
        self.file = tuple(file_obstacles)
        self.base_frame_id = frame_name(base_frame_id)
        self.topic = {}  # name -> Obstacle as received (frame_id: its frame, '' = base)

    def apply(self, obstacles):
        """Take one message's obstacles (a list; empty: clear every obstacle the topic added)."""
        if not obstacles:
            self.topic.clear()
            return
        for obstacle in obstacles:
            self.topic[obstacle.name] = obstacle

    def frames(self):
        """Return the frames (other than the base frame) topic obstacles are given in."""
        return {frame_name(o.frame_id) for o in self.topic.values()
                if frame_name(o.frame_id) not in ('', self.base_frame_id)}

    def resolve(self, tree):
        """Return (the merged obstacles in the base frame, {name: frame} left out).

        :param tree: a :class:`FrameTree` (or anything with its ``lookup``)
        """
        merged = [o for o in self.file if o.name not in self.topic]
        unresolved = {}
        for name, obstacle in self.topic.items():
            frame = frame_name(obstacle.frame_id)
            if frame in ('', self.base_frame_id):
                merged.append(obstacle.moved(np.eye(3), np.zeros(3)) if obstacle.frame_id
                              else obstacle)
                continue
            transform = tree.lookup(frame, self.base_frame_id)
            if transform is None:
                unresolved[name] = frame
            else:
                merged.append(obstacle.moved(*transform))
        return tuple(merged), unresolved
