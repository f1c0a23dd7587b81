"""Opening a recording, a bag, a folder, a session or a descriptors file, and ground truth.

``Opening`` turns a file the user chose into a new document: the recording read off
the UI thread, bag topics asked for, the recording's saved session and (on Yes) its
unsaved work restored through ``gui.model.recording_files``, the journal taken, the
poses found, and the run started. What it restores and why is decided in the model;
the questions and messages are here.

A site (several recordings): a site map (``.graphml``), or several files chosen together
in the open dialog (or dropped together). ``gui.model.site`` plans it (what to map, the site
file the session, autosave and journal hang on) and opens each recording's frames off the
UI thread; the rest is as for one recording, on the site file.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

from PySide6.QtCore import QObject
from PySide6.QtWidgets import QFileDialog, QInputDialog

from engine.errors import InputError
from engine.journal import JournalLocked
from engine.session import Session, is_session_file

from .model.recording_files import Unsaved

OPEN_FILTER = ("Recordings and sessions (*.mp4 *.avi *.mkv *.mov *.webm *.m4v *.bag *.db3 *.mcap "
               "*.panotopo.json *.json *.npz);;Videos (*.mp4 *.avi *.mkv *.mov *.webm *.m4v);;"
               "ROS bags (*.bag *.db3 *.mcap);;Sessions (*.json);;Descriptors (*.npz);;All files (*)")


class Opening(QObject):
    """Opens what the user chose and restores what belongs to it (see the module docstring)."""

    def __init__(self, window) -> None:
        super().__init__(window)
        self.w = window   # the views, the status bar and the messages it shows

    def open_dialog(self) -> None:
        """One file, or several chosen together: one site of those recordings."""
        paths, _ = QFileDialog.getOpenFileNames(self.w, "Open (several recordings: one site)", self.w._last_dir(),
                                                OPEN_FILTER)
        if paths:
            self.open_paths(paths)

    def open_paths(self, paths: list, run: bool = True) -> bool:
        """Open one file as ``open_path`` does, several together as one site of those recordings."""
        paths = [str(p) for p in paths if str(p)]
        if len(paths) <= 1:
            return bool(paths) and self.open_path(paths[0], run=run)
        if not self.w.sessions.maybe_save():
            return False
        try:
            return self._open_site(paths, run=run)
        except InputError as exc:
            self.w.error(str(exc))
            return False

    def open_folder_dialog(self) -> None:
        path = QFileDialog.getExistingDirectory(self.w, "Open folder or ROS2 bag", self.w._last_dir())
        if path:
            self.open_path(path)

    def open_path(self, path: str, topic: Optional[str] = None, pose_topic: Optional[str] = None,
                  run: bool = True) -> bool:
        """Open a recording, a bag, a folder, a session or a descriptors .npz (and run)."""
        if not self.w.sessions.maybe_save():
            return False
        from engine.site import is_site_map

        p = Path(path).expanduser()
        try:
            if p.is_file() and is_session_file(p):
                ok = self._open_session(p, run=run)
            elif is_site_map(p):
                ok = self._open_site([str(p)], run=run)
            else:
                ok = self._open_input(p, topic, pose_topic, run=run)
        except InputError as exc:
            self.w.error(str(exc))
            return False
        if ok:
            self.w._add_recent(str(p))
        return ok

    def _open_input(self, p: Path, topic: Optional[str], pose_topic: Optional[str], run: bool,
                    session: Optional[Session] = None, session_file: Optional[Path] = None) -> bool:
        from engine.pipeline import DescribeSettings, is_descriptor_file

        if not p.exists():
            raise InputError(f"{p}: no such file or directory")
        source, descriptors_file = None, is_descriptor_file(p)
        if descriptors_file:
            from engine.descriptors.base import Descriptors

            descs = Descriptors.load(p)  # validate now: a bad file fails here, not in the worker
            source = self._source_for_descriptors(descs)
            settings = DescribeSettings(descriptor=descs.meta.get("descriptor", self.w.params_panel.descriptor_name()),
                                        interval=float(descs.meta.get("interval", 1.0) or 1.0),
                                        shift=bool(descs.meta.get("shift", True)))
        else:
            if session is None and self._is_bag(p) and topic is None:
                chosen = self._choose_bag_topics(p)
                if chosen is None:
                    return False
                topic, pose_topic = chosen
            source = self._open_recording_in_background(p, topic)
            settings = self._recording_settings(session, topic)

        return self._start_document(p, source, settings, session, session_file, pose_topic, run)

    def _recording_settings(self, session: Optional[Session], topic: Optional[str]):
        """How recordings are described: as the session says, else as the panel says."""
        from engine.pipeline import DescribeSettings

        if session is not None and session.describe:
            return _describe_settings(session.describe, self.w.describe_options)
        params = session.map_params() if session else self.w.params_panel.params()
        descriptor = self.w.params_panel.descriptor_name()
        return DescribeSettings(descriptor=descriptor, interval=self.w.params_panel.interval_value(), topic=topic,
                                shift=params.uses_shift,
                                options=self.w.runs._panel_options(self.w.describe_options, descriptor))

    def _open_site(self, paths: list, run: bool, session: Optional[Session] = None,
                   session_file: Optional[Path] = None) -> bool:
        """Several recordings, or a site map, as one document on the site file (module notes)."""
        from engine.sources import open_recording

        from .background import call_in_background
        from .model.site import open_site, plan_site

        plan = plan_site(paths)   # a recording or descriptors file gone: one line, nothing touched
        site, frames, missing = call_in_background(
            self.w, f"Reading {len(plan.sessions)} recordings…", lambda: open_site(plan, lambda q: open_recording(Path(q))))
        settings = self._recording_settings(session, None)
        if not self._start_document(site.anchor, frames, settings, session, session_file, None, run, site=site):
            frames.close()
            return False
        if missing:
            self.w.warn(missing)
        if not site.new:
            self.w._add_recent(str(site.anchor))
        return True

    def _start_document(self, p: Path, source, settings, session: Optional[Session], session_file: Optional[Path],
                        pose_topic: Optional[str], run: bool, site=None) -> bool:
        """A new document of ``p`` (a recording, or a site's file) shown from ``source``: the
        journal taken, nothing of the previous document kept, saved work restored, the run started."""
        try:
            self.w.files.attach(p)
        except JournalLocked as exc:
            self.w.error(f"{p.name} is open in another panotopo window ({exc.holder}): close it there first")
            return False

        # A new document: nothing of the previous one survives.
        self.w.runner.stop()
        self.w.remapper.stop()
        self.w.similarity_worker.stop()
        self.w.runs._preparing_run = None
        self.w.undo_stack.clear()
        self.w._extra_dirty = False
        self.w.doc.clear_map()
        self.w.doc.set_poses(None, None)
        self.w.doc.session_path = None
        self.w.doc.journal = self.w.files.journal
        self.w.doc.describe_settings = settings
        # A new recording starts from the starting parameters (issue 43, defect 3): never
        # from what was set on the recording open before.
        self.w.doc.params = session.map_params() if session else self.w.runs._start_params
        self.w._pending_decisions = None
        self.w.sessions._pending_view = {}
        self.w.doc.site = site
        self.w.doc.set_source(p, source)
        self.w.doc.mapReplaced.emit()  # views clear
        self.w.curation.select_pair_key(None)   # nothing of the previous recording stays selected (defect 5)
        self.w.params_panel.set_describe(settings.descriptor, settings.interval)
        if site is None:   # a site's ground truth is one file per recording: ``panotopo eval``
            self._load_initial_poses(p, session, pose_topic)
        self._restore_saved_work(p, session, session_file)
        self.w.params_panel.set_params(self.w.doc.params, {})   # unset thresholds: "auto" until the map is built
        self._show_journal_state()
        self.w._update_title()
        self.w.statusBar().showMessage(f"Opened {p.name}", 5000)
        if run:
            self.w.runs.start_run()
        return True

    def _restore_saved_work(self, p: Path, session: Optional[Session], session_file: Optional[Path]) -> None:
        """The recording's saved session, whichever file was opened, and unsaved work only if
        the user says so (issue 43, defect 17): "No" restores nothing and drops it."""
        saved_path = session_file if session is not None else self.w.files.saved_session(p)
        saved = session
        if saved is None and saved_path is not None:
            try:
                saved = Session.load(saved_path)
            except InputError as exc:
                self.w.warn(str(exc))
                saved_path = None
        unsaved, warnings = self.w.files.unsaved(p, saved_path)
        for text in warnings:
            self.w.warn(text)
        if unsaved:
            if self.w._ask_yes_no("Restore unsaved work",
                                f"Unsaved work on {p.name} was found ({unsaved.describe()}). Restore it?"):
                pass
            else:
                if self.w.interactive:
                    self.w.files.discard(p)   # declined: it must not come back on the next open
                unsaved = Unsaved()
        if saved is None and not unsaved:
            return
        restored = self.w.files.restore(unsaved, saved)
        if restored.session is not None and restored.session is not session:
            self.w.doc.params = restored.session.map_params()
        self.w._pending_decisions = restored.decisions
        self.w.sessions._pending_view = dict(restored.session.view) if restored.session is not None else {}
        self.w.doc.session_path = saved_path
        if unsaved:
            self.w._extra_dirty = True
            self.w.statusBar().showMessage(f"Unsaved work restored ({unsaved.describe()}; not saved yet)", 10000)
        elif saved_path is not None:
            self.w.statusBar().showMessage(f"Decisions restored from {saved_path.name}", 8000)
        if restored.skipped:
            self.w.warn(f"{restored.skipped} journal records of {p.name} could not be read and were skipped; "
                      "the others were restored")

    def _show_journal_state(self) -> None:
        problem = self.w.files.problem
        self.w.journal_label.setText("Not journaled" if problem else "")
        self.w.journal_label.setToolTip(problem)
        self.w.journal_label.setVisible(bool(problem))
        if problem:
            self.w.warn(problem)

    def _journal_failed(self, message: str) -> None:
        self.w.files.journal_failed(message)
        self._show_journal_state()

    def _open_session(self, path: Path, run: bool = True) -> bool:
        from engine.site import is_site_map

        session = Session.load(path)
        if is_site_map(session.input_path):
            ok = self._open_site([session.input_path], run=run, session=session, session_file=path)
        else:
            ok = self._open_input(Path(session.input_path), session.describe.get("topic"), None, run=run,
                                  session=session, session_file=path)
        if ok:
            self.w.doc.session_path = path
            self.w._update_title()
        return ok

    def _open_recording_in_background(self, p: Path, topic: Optional[str]):
        """Open and index a recording off the UI thread (a long video or a big bag takes a while)."""
        from engine.sources import open_recording

        from .background import call_in_background

        def open_and_index():
            source = open_recording(p, topic=topic)
            source.stamps()  # the one pass over the recording; cached by the source
            return source

        return call_in_background(self.w, f"Reading {p.name}…", open_and_index)

    def _source_for_descriptors(self, descs):
        """The recording a descriptors file was made from, if it is still there (for the viewer)."""
        src = descs.meta.get("source")
        if not src or not Path(src).exists():
            return None
        try:
            from engine.sources import open_recording

            return open_recording(Path(src), topic=descs.meta.get("topic"))
        except InputError:
            return None

    @staticmethod
    def _is_bag(p: Path) -> bool:
        if p.is_file():
            return p.suffix.lower() in (".bag", ".db3", ".mcap")
        from engine.sources.rosbag import is_ros2_bag_dir

        return p.is_dir() and is_ros2_bag_dir(p)

    def _choose_bag_topics(self, p: Path) -> Optional[tuple[Optional[str], Optional[str]]]:
        from engine.sources import list_image_topics, list_pose_topics

        from .open_dialog import BagTopicDialog, default_topics

        images = list_image_topics(p)
        if not images:
            raise InputError(f"{p}: the bag has no image topics")
        poses = list_pose_topics(p)
        if not self.w.interactive or (len(images) == 1 and not poses):
            return default_topics(images, poses)
        dialog = BagTopicDialog(str(p), images, poses, self.w)
        if dialog.exec() != BagTopicDialog.Accepted:
            return None
        return dialog.chosen()

    def _load_initial_poses(self, p: Path, session: Optional[Session], pose_topic: Optional[str]) -> None:
        from engine.sources import read_poses

        try:
            if session is not None and session.poses_path:
                self.w.doc.set_poses(read_poses(session.poses_path, session.poses_topic),
                                   session.poses_path, session.poses_topic)
            elif pose_topic:
                self.w.doc.set_poses(read_poses(p, pose_topic), str(p), pose_topic)
            else:
                base = p if p.is_dir() else p.parent
                for candidate in (p.with_name(p.stem + ".poses.csv"), p.parent / "poses.csv", base / "poses.csv"):
                    if candidate.is_file():
                        self.w.doc.set_poses(read_poses(candidate), str(candidate))
                        self.w.statusBar().showMessage(f"Loaded ground truth from {candidate.name}", 5000)
                        break
        except InputError as exc:
            self.w.warn(f"Ground-truth poses not loaded: {exc}")

    def load_poses_dialog(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self.w, "Load ground-truth poses", self.w._last_dir(),
                                              "Poses (*.csv *.bag *.db3 *.mcap);;All files (*)")
        if path:
            self.load_poses(path)

    def load_poses(self, path: str, topic: Optional[str] = None) -> bool:
        from engine.sources import list_pose_topics, read_poses

        p = Path(path)
        if self.w.doc.site is not None:
            self.w.error("A site's ground truth is one file per recording: evaluate it with "
                         "panotopo eval SITE.graphml --poses A_poses.csv --poses B_poses.csv")
            return False
        try:
            if topic is None and (self._is_bag(p)):
                topics = [t for t, _m, _c in list_pose_topics(p)]
                if not topics:
                    raise InputError(f"{p}: the bag has no pose topics")
                if len(topics) > 1 and self.w.interactive:
                    topic, ok = QInputDialog.getItem(self.w, "Pose topic", "Ground-truth pose topic:", topics, 0, False)
                    if not ok:
                        return False
                else:
                    topic = topics[0]
            poses = read_poses(p, topic)
        except InputError as exc:
            self.w.error(str(exc))
            return False
        self.w.doc.set_poses(poses, str(p), topic)
        self.w._extra_dirty = True
        self.w._update_title()
        self.w.statusBar().showMessage(f"Ground truth loaded: {len(poses)} poses from {p.name}", 5000)
        return True


def _describe_settings(data: dict, default_options: dict):
    from engine.pipeline import DescribeSettings

    known = set(DescribeSettings.__dataclass_fields__)
    values = {k: v for k, v in data.items() if k in known}
    if not values.get("options") and default_options:
        values["options"] = dict(default_options)
    try:
        return DescribeSettings(**values)
    except TypeError:
        raise InputError("the session's describe settings are malformed") from None
