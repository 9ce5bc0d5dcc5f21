# SPDX-License-Identifier: GPL-3.0-or-later
"""groom's progress reports shown the way Blender shows long work: the progress indicator
(window_manager.progress_*, the counter in the mouse cursor) and a line of status text."""


class BlenderProgress:
    """A callable(fraction in [0, 1], stage) for groom's `progress=`; use as a context
    manager so the indicator and the status text go away however the work ends.

    window_manager: context.window_manager; workspace: context.workspace or None (no status
    text then); label: what the work is ("Generating hair")."""

    def __init__(self, window_manager, workspace, label):
        self.window_manager, self.workspace, self.label = window_manager, workspace, label
        self.shown = False

    def __call__(self, fraction, stage):
        if not self.shown:
            self.window_manager.progress_begin(0, 100)
            self.shown = True
        percent = min(max(int(round(100.0 * fraction)), 0), 100)
        self.window_manager.progress_update(percent)
        if self.workspace is not None:
            self.workspace.status_text_set(f"{self.label}: {stage} ({percent} %)")

    def close(self):
        if self.shown:
            self.window_manager.progress_end()
            if self.workspace is not None:
                self.workspace.status_text_set(None)
            self.shown = False

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False
