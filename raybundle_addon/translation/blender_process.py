"""A script run by Blender in a process of its own, while the caller goes on.

Blender evaluates what it defines (a world's node tree, a material input's node graph) by
rendering or baking with Cycles; a render cannot start another render in the same process, so
the script (:mod:`.world_render`, :mod:`.material_bake`) runs in a child process: the
``blender`` binary in background mode when the add-on runs inside Blender, this Python (which
imports the ``bpy`` module) otherwise.  Its inputs and outputs live in a temporary folder the
caller fills first and reads after :meth:`BlenderProcess.wait`; :meth:`BlenderProcess.close`
removes it.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time


class BlenderProcessError(RuntimeError):
    """The script did not run to its end (one-line reason)."""


def temporary_folder(prefix):
    """A :class:`tempfile.TemporaryDirectory` for one process's inputs and outputs."""
    return tempfile.TemporaryDirectory(prefix=prefix)


class BlenderProcess:
    """``script`` (a file beside this module) run with ``args`` by Blender, its log in
    ``folder``/log.txt, given up after ``timeout`` seconds.  The script lowers its own priority
    on POSIX (``os.nice``); on Windows the process starts below normal, or ``lowest`` at idle
    priority (a render whose result is read last)."""

    def __init__(self, script, args, folder, timeout, lowest=False):
        import bpy

        self.folder, self.timeout = folder, float(timeout)
        path = os.path.join(os.path.dirname(os.path.abspath(__file__)), script)
        binary = bpy.app.binary_path
        if binary and os.path.basename(binary).lower().startswith("blender"):
            cmd = [binary, "-b", "--factory-startup", "--python-exit-code", "1", "--python", path, "--", *args]
        else:                                 # the bpy module: this Python imports bpy
            cmd = [sys.executable, path, *args]
        # the log to a file: a pipe nobody reads while the caller works would fill and stall it.
        # The script lowers its own priority on POSIX (no preexec_fn in a process with threads)
        lower = dict(creationflags=subprocess.IDLE_PRIORITY_CLASS if lowest else subprocess.BELOW_NORMAL_PRIORITY_CLASS) \
            if os.name == "nt" else {}
        self._started = time.perf_counter()
        try:
            with open(os.path.join(folder.name, "log.txt"), "w") as log:
                self._proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT,
                                              stdin=subprocess.DEVNULL, **lower)
        except OSError as e:
            folder.cleanup()
            raise BlenderProcessError(f"Blender did not start: {e}") from None

    def poll(self):
        """The exit code, or None while it runs."""
        return self._proc.poll()

    def wait(self, outputs=()):
        """Wait for the end (at most :attr:`timeout` seconds from the start); raises
        :class:`BlenderProcessError` when it failed or any of ``outputs`` (paths) is missing."""
        try:
            self._proc.wait(timeout=max(0.0, self.timeout - (time.perf_counter() - self._started)))
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()
            raise BlenderProcessError(f"it did not finish in {self.timeout:g} s") from None
        if self._proc.returncode != 0 or not all(os.path.exists(p) for p in outputs):
            with open(os.path.join(self.folder.name, "log.txt"), errors="replace") as f:
                lines = [x for x in f.read().splitlines() if x.strip()]
            raise BlenderProcessError(lines[-1] if lines else f"exit code {self._proc.returncode}")

    def close(self):
        """Stop the process if it still runs and remove its folder."""
        if self._proc.poll() is None:
            self._proc.kill()
            self._proc.wait()
        self.folder.cleanup()
