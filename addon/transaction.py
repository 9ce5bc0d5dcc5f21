# SPDX-License-Identifier: GPL-3.0-or-later
"""All or nothing for one press of an operator: when it fails midway, every datablock it made
is removed and everything it changed is put back, so the file is exactly as it was.

    with transaction() as tx:
        tx.keep_settings(scalp)     # its Key-Strand Hair settings come back
        tx.keep_transform(hair)     # its parent and matrices come back
        tx.keep_curves(hair)        # its Curves datablock comes back, as it was
        ... write ...

An exception inside the block rolls back and propagates. The error policy is here too, one
for the whole extension: a bad input (hairio.InputError) is the user's to fix and is reported
with its message; anything else is a bug and says so (`report_internal_error`). Operators get
both from `reports_errors`, the decorator every execute() wears; live update and the mirror
keeping, which run in handlers with no operator to report on, use `report_background` (the
panel shows what it noted).
Datablocks made inside the block need no bookkeeping: every ID that was not in the file when
the block began is removed on rollback. A `transaction()` opened inside another joins it, so
a writer such as hair.write_hair is all or nothing alone (live update) and as a part of an
operator's larger change alike.
"""
import contextlib
import functools
import traceback

import bpy
from hairio import InputError

_active = None


def _all_ids():
    """session_uid -> ID of every datablock in the file (every collection of bpy.data)."""
    out = {}
    for prop in bpy.types.BlendData.bl_rna.properties:
        if prop.type != 'COLLECTION':
            continue
        for block in getattr(bpy.data, prop.identifier):
            if isinstance(block, bpy.types.ID):
                out[block.session_uid] = block
    return out


def _settings_values(settings):
    """The writable values of a property group, arrays as tuples, ID pointers as the ID."""
    out = {}
    for prop in settings.bl_rna.properties:
        if prop.identifier == "rna_type" or prop.is_readonly or prop.type == 'COLLECTION':
            continue
        value = getattr(settings, prop.identifier)
        if prop.type == 'POINTER' and value is not None and not isinstance(value, bpy.types.ID):
            continue  # a nested group: not used by these settings
        if getattr(prop, "is_array", False):
            value = tuple(value)
        out[prop.identifier] = value
    return out


class Transaction:
    """The undo log of one press; use through `transaction()`."""

    def __init__(self):
        self._before = set(_all_ids())
        self._undo = []        # callables putting back what was changed, run last first
        self._on_commit = []   # callables dropping the copies kept for the undo
        self._survivors = set()  # session_uids of datablocks made here that a rollback keeps

    def keep_settings(self, obj):
        """Put back every Key-Strand Hair setting of `obj` on rollback."""
        settings = obj.keystrand_hair
        saved = _settings_values(settings)

        def undo():
            # Twice: a setter may rewrite others (Head Axes rewrites Up and Front), and the
            # second pass puts those back too. Only values that differ are set, so no update
            # callback runs for a setting that never changed.
            for _ in range(2):
                now = _settings_values(settings)
                for name, value in saved.items():
                    if now.get(name) != value:
                        setattr(settings, name, value)
        self._undo.append(undo)

    def keep_transform(self, obj):
        """Put back `obj`'s parent and matrices on rollback."""
        parent = obj.parent
        parent_inverse = obj.matrix_parent_inverse.copy()
        basis = obj.matrix_basis.copy()

        def undo():
            obj.parent = parent
            obj.matrix_parent_inverse = parent_inverse
            obj.matrix_basis = basis
        self._undo.append(undo)

    def keep_curves(self, obj):
        """Put back `obj`'s Curves datablock as it is now on rollback, even if it was filled
        in place or replaced by another one meanwhile.

        The copy costs no memory at first (Blender shares the arrays until one side writes);
        on commit it is dropped. A writer that removes an attribute before writing it anew
        (blender_curves.drop_written_attributes) gets fresh memory for it instead of a
        copy of the shared array it is about to overwrite."""
        original = obj.data
        name, fake_user = original.name, original.use_fake_user
        backup = original.copy()

        def undo():
            current = obj.data
            current.user_remap(backup)
            if current.users == 0:
                bpy.data.hair_curves.remove(current)
            backup.name = name
            backup.use_fake_user = fake_user
            self._survivors.add(backup.session_uid)

        def drop():
            bpy.data.hair_curves.remove(backup)
        self._undo.append(undo)
        self._on_commit.append(drop)

    def undo(self, fn):
        """Run `fn` on rollback (before the datablocks made here are removed)."""
        self._undo.append(fn)

    def on_commit(self, fn):
        """Run `fn` once every change of the press has succeeded (for steps that cannot be
        undone, such as removing what the change replaces)."""
        self._on_commit.append(fn)

    def commit(self):
        for fn in self._on_commit:
            fn()

    def rollback(self):
        for fn in reversed(self._undo):
            try:
                fn()
            except Exception:  # put back as much as can be; the first error is the one reported
                traceback.print_exc()
        made = [block for uid, block in _all_ids().items()
                if uid not in self._before and uid not in self._survivors]
        if made:
            bpy.data.batch_remove(made)


def report_internal_error(op, error):
    """Report on operator `op` an error that is not the user's (a bug) after its press was
    rolled back: the message says nothing was changed, the console has the traceback for the
    bug report."""
    traceback.print_exception(error)
    op.report({'ERROR'}, f"Internal error in {op.bl_label} ({type(error).__name__}: {error}); "
                         "nothing was changed. Please report this, with the traceback printed "
                         "in Blender's system console")


def reports_errors(execute=None, *, failures=()):
    """Decorator of an operator's execute(): the press is one transaction, and nothing is
    raised into the UI. An InputError is reported as the user's to fix (its message names
    the input and the fix); an exception matching `failures`, pairs (types, message(op,
    error)) for the world outside failing rather than the user or the code (a file that
    cannot be written, a renderer process that died), with its own message; anything else
    as a bug, through report_internal_error. Either way the press is rolled back and returns
    {'CANCELLED'}. `types` may be a callable returning the types (for optional modules)."""
    def wrap(fn):
        @functools.wraps(fn)
        def run(op, context):
            try:
                with transaction():
                    return fn(op, context)
            except InputError as e:
                op.report({'ERROR'}, str(e))
            except Exception as e:
                for types, message in failures:
                    if not isinstance(types, (type, tuple)):
                        types = types()
                    if isinstance(e, types):
                        op.report({'ERROR'}, message(op, e))
                        break
                else:
                    report_internal_error(op, e)
            return {'CANCELLED'}
        return run
    return wrap if execute is None else wrap(execute)


# What went wrong in work no operator runs (live update, mirrored keys), per scalp and task,
# until that task next succeeds: (scalp session_uid, task) -> message.
_background = {}


def report_background(scalp, task, error):
    """Note an error of `task` (e.g. "Live update") on `scalp` outside any press, for the
    panel to show: an InputError as its message (the task waits until the input is fixed;
    the hair keeps its last good state), anything else as a bug, its traceback printed to
    the console."""
    if isinstance(error, InputError):
        message = f"{task} waits: {error}"
    else:
        traceback.print_exception(error)
        message = (f"Internal error in {task} ({type(error).__name__}: {error}). Please report this, "
                   "with the traceback printed in Blender's system console")
    if _background.get((scalp.session_uid, task)) != message:
        _background[scalp.session_uid, task] = message
        _redraw_hair_tab()


def clear_background(scalp, task):
    """`task` succeeded on `scalp`: its note goes."""
    if _background.pop((scalp.session_uid, task), None) is not None:
        _redraw_hair_tab()


def _redraw_hair_tab():
    # The notes change in handlers and timers, which redraw nothing by themselves.
    for window in getattr(bpy.context.window_manager, "windows", ()):
        for area in window.screen.areas:
            if area.type == 'VIEW_3D':
                area.tag_redraw()


def background_errors(scalp):
    """The notes report_background holds for `scalp`, oldest first."""
    return [m for (uid, _task), m in _background.items() if uid == scalp.session_uid]


def forget_background(scalp=None):
    """Drop the notes of one scalp (of every scalp when None): a file was loaded, or live
    update switched off."""
    for key in [k for k in _background if scalp is None or k[0] == scalp.session_uid]:
        del _background[key]


@contextlib.contextmanager
def transaction():
    """The press's Transaction: a new one, or the one already open (joined)."""
    global _active
    if _active is not None:
        yield _active
        return
    tx = _active = Transaction()
    try:
        yield tx
    except BaseException:
        _active = None
        tx.rollback()
        raise
    _active = None
    tx.commit()
