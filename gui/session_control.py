"""Saving the user's work and exporting it.

``SessionControl`` builds the session of now, writes it (and the autosave) through
``gui.model.recording_files`` (regular files of ours only), asks before unsaved work
is dropped, restores the view a session kept, and exports the corrected graph, a
picture of it and the evaluation plot.

A site's session is the session of its site file; its view names frames as each
recording's own (``selected_sessions``, ``frame_session``) and keeps the pair filter.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

from PySide6.QtCore import QObject
from PySide6.QtWidgets import QFileDialog, QMessageBox

from engine.errors import InputError
from engine.session import Session, session_path_for



class SessionControl(QObject):
    """Saving, autosaving, asking before losing work, exporting (see the module docstring)."""

    def __init__(self, window) -> None:
        super().__init__(window)
        self.w = window   # the views, the status bar and the messages it shows
        self._pending_view = {}

    def is_modified(self) -> bool:
        return not self.w.undo_stack.isClean() or self.w._extra_dirty

    def current_session(self) -> Session:
        settings = self.w.doc.describe_settings
        decisions = self.w.doc.decisions() if self.w.doc.has_map else (self.w._pending_decisions or {})
        key = self.w.curation.selected_key()
        frame = self.w.frame_viewer.current_frame
        view = {"frame": frame if frame >= 0 else None, "tab": self.w.tabs.currentIndex(),  # -1: no frames shown
                "filter": self.w.loop_table.filter.currentIndex(),
                "selected": list(key) if key is not None else None}
        site = self.w.doc.site
        if site is not None:   # frames as each recording's own (a site frame is no name on disk)
            if key is not None:
                view["selected"], view["selected_sessions"] = self.w.doc.address(key)
            if frame >= 0:
                view["frame_session"], view["frame"] = site.local(frame)
            pair = self.w.loop_table.pair_filter.currentData()
            view["pair"] = list(pair) if pair else None
        return Session(input_path=str(self.w.doc.input_path), describe=settings.as_dict() if settings else {},
                       params=self.w.doc.params.as_dict(), decisions=decisions, poses_path=self.w.doc.poses_path,
                       poses_topic=self.w.doc.poses_topic, view=view)

    def save_session(self, path: Optional[str] = None) -> bool:
        if self.w.doc.input_path is None:
            return False
        target = Path(path) if path else (self.w.doc.session_path or session_path_for(self.w.doc.input_path))
        try:
            self.w.files.save(self.current_session(), target)
        except (OSError, InputError) as exc:
            self.w.error(f"Could not save the session to {target}: {getattr(exc, 'strerror', None) or exc}")
            return False
        self.w.doc.session_path = target
        self.w.undo_stack.setClean()
        self.w._extra_dirty = False
        self.w._update_title()
        self.w._add_recent(str(target))
        self.w.statusBar().showMessage(f"Session saved to {target}", 5000)
        return True

    def save_session_as(self) -> bool:
        if self.w.doc.input_path is None:
            return False
        start = str(self.w.doc.session_path or session_path_for(self.w.doc.input_path))
        path, _ = QFileDialog.getSaveFileName(self.w, "Save session", start, "Sessions (*.json)")
        return self.save_session(path) if path else False

    def autosave(self) -> None:
        """Write unsaved work to the autosave file (never the user's session file)."""
        if self.w.doc.input_path is None or not self.is_modified():
            return
        try:
            self.w.files.autosave(self.current_session())
        except (OSError, InputError) as exc:
            self.w.statusBar().showMessage(f"Autosave failed: {exc}", 8000)

    def _restore_view(self) -> None:
        view, self._pending_view = self._pending_view, {}
        if not view:
            return
        if isinstance(view.get("tab"), int):
            self.w.tabs.setCurrentIndex(view["tab"])
        if isinstance(view.get("filter"), int):
            self.w.loop_table.filter.setCurrentIndex(view["filter"])
        site = self.w.doc.site
        if site is not None and isinstance(view.get("pair"), list) and len(view["pair"]) == 2:
            self.w.loop_table.set_pair(tuple(str(n) for n in view["pair"]))
        try:
            if isinstance(view.get("selected"), list) and len(view["selected"]) == 2:
                sessions = view.get("selected_sessions") if site is not None else None
                names = sessions if isinstance(sessions, list) and len(sessions) == 2 else None
                self.w.curation.select_loop(self.w.doc.key_of_address([int(f) for f in view["selected"]], names))
            if isinstance(view.get("frame"), int) and view["frame"] >= 0:  # after the selection, which moves it
                frame = view["frame"]
                if site is not None:
                    frame = site.place(str(view.get("frame_session") or site.names[0]), frame)
                self.w.frame_viewer.show_frame(frame)
        except InputError:   # a recording the site no longer has: the view is only a convenience
            pass

    def maybe_save(self) -> bool:
        """Ask before unsaved work is dropped; False means stay."""
        if not self.is_modified() or self.w.doc.input_path is None:
            return True
        answer = QMessageBox.question(
            self.w, "Unsaved changes",
            f"Save your decisions on {self.w.doc.input_path.name} before closing it?",
            QMessageBox.Save | QMessageBox.Discard | QMessageBox.Cancel, QMessageBox.Save)
        if answer == QMessageBox.Save:
            return self.save_session()
        if answer == QMessageBox.Discard:
            self.w.files.discard(self.w.doc.input_path)  # discarded: they must not come back on the next open
            self.w.undo_stack.setClean()
            self.w._extra_dirty = False
            return True
        return False

    def export_graphml(self, path: str) -> bool:
        if not self.w.doc.has_map:
            self.w.statusBar().showMessage("Nothing to export: run the engine first", 5000)
            return False
        try:
            self.w.doc.topomap.write_graphml(path, keep_rejected=False)
        except (InputError, OSError) as exc:
            self.w.error(f"Export failed: {exc}")
            return False
        self.w.statusBar().showMessage(f"Corrected graph written to {path}", 6000)
        return True

    def export_graphml_dialog(self) -> None:
        if not self.w.doc.has_map:
            return
        start = str(Path(self.w.doc.input_path).with_suffix(".graphml"))
        if self.w.doc.site is not None:   # never over the site file itself
            start = str(Path(self.w.doc.input_path).with_suffix(".corrected.graphml"))
        path, _ = QFileDialog.getSaveFileName(self.w, "Export corrected graph", start, "GraphML (*.graphml)")
        if path:
            self.export_graphml(path)

    def export_graph_png(self, path: str) -> bool:
        ok = self.w.graph_view.plot.grab().save(path)
        if not ok:
            self.w.error(f"Could not write {path}")
        return bool(ok)

    def export_png_dialog(self) -> None:
        start = str(Path(self.w.doc.input_path or "graph").with_suffix(".png"))
        path, _ = QFileDialog.getSaveFileName(self.w, "Export graph picture", start, "PNG (*.png)")
        if path:
            self.export_graph_png(path)

    def export_plot_dialog(self) -> None:
        if not self.w.doc.has_map:
            return
        from engine.plots import plot_map

        start = str(Path(self.w.doc.input_path).with_suffix(".map.png"))
        path, _ = QFileDialog.getSaveFileName(self.w, "Export evaluation plot", start, "PNG (*.png)")
        if path:
            try:
                plot_map(self.w.doc.topomap, self.w.doc.poses, self.w.doc.evaluation, path)
            except (InputError, OSError) as exc:
                self.w.error(f"Export failed: {exc}")
