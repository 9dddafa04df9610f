#!/usr/bin/python3
"""The DISPLAY program of pkmcal's headless LinuxCNC runs (:mod:`pkmcal.controllers.linuxcnc`).

LinuxCNC's start script runs the INI's ``[DISPLAY] DISPLAY`` as ``PROGRAM -ini INIFILE``
(``scripts/linuxcnc.in``, "all other displays are assumed to be commands on the PATH") and
shuts LinuxCNC down when it exits. This program drives the controller through LinuxCNC's
Python module (``linuxcnc.command``, ``linuxcnc.stat``: the NML interface every GUI uses):

1. leaves E-stop, switches the machine on and homes all joints (``command.home(-1)``);
2. world mode: per pose, MDI ``G53 G0 X Y Z A B C`` (machine coordinates, ``G49 G92.1``
   first so no tool length or G92 offset moves the pose), waits until motion is done and
   reads ``stat.joint_actual_position`` (the strut lengths genhexkins' inverse kinematics
   gave) and ``stat.actual_position``;
3. joint mode (``teleop_enable(0)``): per row of joint targets, jogs every joint by the
   increment to its target (``JOG_INCREMENT``, joint jog), waits until the joints stop and
   reads the joints held and ``stat.actual_position`` (genhexkins' forward kinematics of
   them).

It reads ``pkmcal-job.json`` beside the INI file and writes ``pkmcal-result.json`` there
(atomically), then exits, which lets LinuxCNC clean up. It is run by Debian's
``/usr/bin/python3`` (where the ``linuxcnc`` module is) and imports nothing of pkmcal. Any
failure is written into the result as ``error`` (one line) instead of a traceback.
"""

import json
import os
import sys
import time

JOB_FILE = "pkmcal-job.json"
RESULT_FILE = "pkmcal-result.json"
PID_FILE = "pkmcal-display.pid"
#: Polls (5 ms apart) with the joints unchanged before a position is read.
STABLE_POLLS = 6


class DriverError(Exception):
    pass


def _ini_dir(argv):
    for k, arg in enumerate(argv[:-1]):
        if arg == "-ini":
            return os.path.dirname(os.path.abspath(argv[k + 1]))
    raise DriverError("started without '-ini INIFILE'")


class Machine:
    def __init__(self, linuxcnc, timeout):
        self.lc = linuxcnc
        self.c = linuxcnc.command()
        self.s = linuxcnc.stat()
        self.e = linuxcnc.error_channel()
        self.timeout = timeout

    def poll(self):
        self.s.poll()
        err = self.e.poll()
        if err:
            kind, text = err
            if kind in (self.lc.NML_ERROR, self.lc.OPERATOR_ERROR):
                raise DriverError("LinuxCNC error: " + " ".join(str(text).split()))
        return self.s

    def wait(self, what, ok, timeout=None):
        end = time.monotonic() + (self.timeout if timeout is None else timeout)
        while time.monotonic() < end:
            if ok(self.poll()):
                return
            time.sleep(0.005)
        raise DriverError("timed out waiting for " + what)

    def settled(self, s):
        return s.inpos and s.queue == 0 and all(j["velocity"] == 0.0 for j in s.joint[:s.joints])

    def settle(self, what, extra=lambda s: True):
        """Wait until motion is done (in position, empty queue, joints at rest, ``extra``)
        and the joints have not changed for STABLE_POLLS polls in a row: a status read
        between the end of one command and the start of its motion is not taken."""
        state = {"last": None, "same": 0}

        def done(s):
            now = tuple(s.joint_actual_position[:s.joints])
            quiet = self.settled(s) and extra(s) and now == state["last"]
            state["same"] = state["same"] + 1 if quiet else 0
            state["last"] = now
            return state["same"] >= STABLE_POLLS

        self.wait(what, done)

    def start(self):
        lc = self.lc
        self.wait("the task to answer", lambda s: s.task_state in (lc.STATE_ESTOP, lc.STATE_ESTOP_RESET,
                                                                       lc.STATE_OFF, lc.STATE_ON))
        self.c.state(lc.STATE_ESTOP_RESET)
        self.wait("E-stop reset", lambda s: s.task_state != lc.STATE_ESTOP)
        self.c.state(lc.STATE_ON)
        self.wait("machine on", lambda s: s.task_state == lc.STATE_ON)
        self.c.mode(lc.MODE_MANUAL)
        self.wait("manual mode", lambda s: s.task_mode == lc.MODE_MANUAL)
        self.c.teleop_enable(0)
        self.wait("joint mode", lambda s: s.motion_mode == lc.TRAJ_MODE_FREE)
        self.c.home(-1)
        self.settle("homing", lambda s: all(s.homed[:s.joints]))

    def snapshot(self):
        s = self.poll()
        return {"joints": list(s.joint_actual_position[:s.joints]), "world": list(s.actual_position[:6])}

    def mdi(self, text):
        lc = self.lc
        self.c.mdi(text)
        self.c.wait_complete(self.timeout)
        self.settle("'%s' to finish" % text, lambda s: s.interp_state == lc.INTERP_IDLE)

    def world_moves(self, poses, units_code):
        lc = self.lc
        self.c.mode(lc.MODE_MDI)
        self.wait("MDI mode", lambda s: s.task_mode == lc.MODE_MDI)
        self.mdi(units_code + " G90 G49 G92.1")
        out = []
        for pose in poses:
            self.mdi("G53 G0 " + " ".join("%s%.17g" % (k, v) for k, v in zip("XYZABC", pose)))
            out.append(self.snapshot())
        return out

    def joint_moves(self, targets, velocity):
        lc = self.lc
        self.c.mode(lc.MODE_MANUAL)
        self.wait("manual mode", lambda s: s.task_mode == lc.MODE_MANUAL)
        self.c.teleop_enable(0)
        self.wait("joint mode", lambda s: s.motion_mode == lc.TRAJ_MODE_FREE)
        out = []
        for target in targets:
            held = self.poll().joint_actual_position
            steps = [value - held[n] for n, value in enumerate(target)]
            longest = max(abs(d) for d in steps)
            for n, step in enumerate(steps):
                if step != 0.0:
                    # each joint's speed in proportion to its step, so that the joints move
                    # together along the straight line in joint space (one joint far ahead of
                    # the others can reach joint values no pose has, where genhexkins' forward
                    # kinematics fails); the jog's direction is the sign of its velocity, its
                    # distance the increment (LinuxCNC src/emc/motion/command.c, JOG_INCR)
                    v = velocity * abs(step) / longest
                    self.c.jog(lc.JOG_INCREMENT, 1, n, v if step > 0 else -v, abs(step))
            self.settle("the joint jogs to stop")
            out.append(self.snapshot())
        return out


def run(argv):
    here = _ini_dir(argv)
    with open(os.path.join(here, PID_FILE), "w") as fh:   # the harness stops us (and so LinuxCNC) by this
        fh.write(str(os.getpid()))
    with open(os.path.join(here, JOB_FILE)) as fh:
        job = json.load(fh)
    result = {"error": None}
    try:
        import linuxcnc

        m = Machine(linuxcnc, float(job.get("timeout", 30.0)))
        m.start()
        result["home"] = m.snapshot()
        result["world_mode"] = m.world_moves(job.get("poses", []), job["units_code"])
        result["joint_mode"] = m.joint_moves(job.get("joint_targets", []), float(job["jog_velocity"]))
    except Exception as exc:  # reported to the caller as one line, never a traceback here
        result["error"] = " ".join(("%s: %s" % (type(exc).__name__, exc)).split())
    tmp = os.path.join(here, RESULT_FILE + ".tmp")
    with open(tmp, "w") as fh:
        json.dump(result, fh)
    os.replace(tmp, os.path.join(here, RESULT_FILE))
    return 0 if result["error"] is None else 1


if __name__ == "__main__":
    sys.exit(run(sys.argv))
