"""Runs and re-maps: the pipeline run, its progress, and a parameter change.

``RunControl`` starts the run (``gui.worker.RunController``), shows its progress in
the status bar, prepares the finished map off the UI thread, and rebuilds the map on
a parameter change (``gui.background.Worker``, newest request wins; the job gets a
copy of the decisions, ``MapDocument.remap_job``). Whether a change needs a new
describe or only a re-map, and which thresholds are known, is decided in
``gui.model.run_plan`` and ``engine.pipeline.descriptors_fit``.

A site (several recordings) runs ``engine.site.map_site`` (the CLI's orchestrator) and
re-maps its concatenated descriptors per recording (``gui.model.site.site_remap``); a
site opened from recordings chosen together gets its site file written once its first
map is there (``gui.model.site``), so that it can be reopened with its work.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

from PySide6.QtCore import QObject

from engine.errors import InputError
from engine.params import MapParams

from .commands import ChangeParams
from .model import run_plan
from .model.run_plan import needs_remap
from .params_panel import photometric_applies
from .worker import FinishedRun, RunJob


class RunControl(QObject):
    """Runs, their progress, and re-maps on a parameter change (see the module docstring)."""

    def __init__(self, window) -> None:
        super().__init__(window)
        self.w = window   # the views, the status bar and the messages it shows
        self._preparing_run = None
        self._defaults = {}
        self._start_params = MapParams()
        self._progress_stage = ""
        self._stage_started = 0.0

    def _apply_default_settings(self) -> None:
        """Start from resources/default_settings.json (map parameters, descriptor, interval, distance)."""
        known = set(MapParams.__dataclass_fields__)
        try:
            params = MapParams(**{k: v for k, v in self.w.defaults["map"].items() if k in known})
        except TypeError:
            params = MapParams()
        if params.method not in __import__("engine.params", fromlist=["METHODS"]).METHODS:
            params = MapParams()
        self.w.doc.params = params
        self._start_params = params   # what a newly opened recording starts from
        self.w.params_panel.set_params(params, {})
        describe = self.w.defaults["describe"]
        self.w.params_panel.set_describe(str(describe.get("descriptor", self.w.params_panel.descriptor_name())),
                                       float(describe.get("interval", 1.0)))
        self.w.doc.dist_th = float(self.w.defaults["eval"].get("dist_th", 1.0))

    def start_run(self) -> None:
        from engine.pipeline import DescribeSettings

        if self.w.doc.input_path is None:
            self.w.statusBar().showMessage("Open a recording first", 5000)
            return
        old = self.w.doc.describe_settings or DescribeSettings()
        descriptor = self.w.params_panel.descriptor_name()
        interval = self.w.params_panel.interval_value()
        if self.w.doc.descs is not None and self.w.doc.descriptors_only():
            descriptor, interval = old.descriptor, old.interval  # a descriptors file is what it is
        options = self._panel_options(old.options if descriptor == old.descriptor else self.w.describe_options,
                                      descriptor)
        settings = DescribeSettings(descriptor=descriptor, interval=interval, topic=old.topic,
                                    shift=self.w.doc.params.uses_shift, options=options)
        self._start(settings)

    def _panel_options(self, options: dict, descriptor: str) -> dict:
        """The user's describe ``options`` with the panel's photometric choice: named when
        chosen, left to the method (``engine.pipeline.method_settings``) when not."""
        out = {k: v for k, v in options.items() if k != "photometric"}
        choice = self.w.params_panel.photometric_choice()
        if choice is not None and photometric_applies(descriptor):
            out["photometric"] = choice
        return out

    def _start(self, settings) -> None:
        from engine.descriptors.cache import DescriptorCache

        if self.w.runner.running:
            self.w.runner.cancel()   # the new run waits for the old one to stop at its next check
        self._preparing_run = None  # a new run supersedes the map being prepared
        self._show_progress(True)
        self._progress_stage = ""
        self._stage_started = time.monotonic()
        self.w.progress_bar.setRange(0, 0)
        self.w.progress_bar.setFormat("starting…")
        self.w.eta_label.setText("")
        site = self.w.doc.site
        job = RunJob(list(site.inputs) if site is not None else Path(self.w.doc.input_path), settings,
                     self.w.doc.params, DescriptorCache(self.w.cache_root))
        self.w.statusBar().showMessage("Running the engine…")
        self.w.runner.start(job)
        self.w._update_actions()

    def cancel_run(self) -> None:
        if self.w.runner.running:
            self.w.runner.cancel()
            self.w.cancel_button.setEnabled(False)
            self.w.statusBar().showMessage("Cancelling…")

    def _on_progress(self, done: int, total: int, stage: str) -> None:
        now = time.monotonic()
        if stage != self._progress_stage:
            self._progress_stage, self._stage_started = stage, now
        if total > 0:
            self.w.progress_bar.setRange(0, total)
            self.w.progress_bar.setValue(min(done, total))
            self.w.progress_bar.setFormat(f"{stage}: {done}/{total}")
            elapsed = now - self._stage_started
            if done > 0 and elapsed > 0.5:
                self.w.eta_label.setText(f"ETA {_duration(elapsed * (total - done) / done)}")
        else:
            self.w.progress_bar.setRange(0, 0)
            self.w.progress_bar.setFormat(stage)

    def _on_run_finished(self, result: FinishedRun) -> None:
        """The run's map is prepared off the UI thread too (decisions applied, rows, layout)."""
        # Decisions survive a re-run: the current ones, or those of the session just opened.
        pending, self.w._pending_decisions = self.w._pending_decisions, None
        self._preparing_run = result
        self.w.progress_bar.setRange(0, 0)
        self.w.progress_bar.setFormat("preparing the map")
        job = self.w.doc.remap_job(lambda: result.topomap, pending)
        self.w.remapper.submit(job, lambda prepared: self._run_prepared(result, pending, prepared),
                             lambda exc: self._run_prepare_failed(result, exc))

    def _run_prepare_failed(self, result: FinishedRun, exc: BaseException) -> None:
        if self._preparing_run is result:
            self._preparing_run = None
            self._on_run_failed(f"unexpected error: {exc.__class__.__name__}: {exc}")

    def _run_prepared(self, result: FinishedRun, pending, prepared) -> None:
        from engine.pipeline import descriptor_defaults

        if self._preparing_run is not result:
            return  # another run or another recording came in meanwhile
        if pending is None and not self.w.doc.is_current(prepared):  # decided on the old map meanwhile
            self._on_run_finished(result)  # prepare again, with those decisions
            return
        self._preparing_run = None
        self._show_progress(False)
        site = self.w.doc.site
        if site is not None:
            if result.sessions != site.names:   # the site file changed under the open site
                self._on_run_failed(f"the recordings of {site.anchor.name} changed while it was open: open it again")
                return
            site.row_starts = list(result.row_starts)
        self.w.doc.describe_settings = result.job.settings
        self._defaults = descriptor_defaults(result.descs, result.job.params.method)   # verified: none to calibrate
        self.w.doc.install(prepared, result.descs)
        self._set_known_shifts(result.descs)
        if needs_remap(result.job.params, self.w.doc.params):
            # The user changed a map parameter while the run was going: honour it (off the UI thread).
            self._remap(self.w.doc.params)
        elif result.job.params != self.w.doc.params:
            # ... or the method, to one that needs other descriptors: describe again, or map a .npz.
            self._apply_params(result.job.params, self.w.doc.params)
        self.w.params_panel.set_describe(result.job.settings.descriptor, result.job.settings.interval)
        self.w.params_panel.set_photometric(result.job.settings.options.get("photometric"))
        self.w.params_panel.set_params(self.w.doc.params, self._used_defaults())
        self.w.sessions._restore_view()
        self.w.statusBar().showMessage(
            f"Map built in {result.seconds:.1f} s: {self.w.doc.node_count()} nodes, "
            f"{len(self.w.doc.loop_rows())} loop candidates" + "".join(f" · {n}" for n in result.notes), 10000)
        if site is not None and site.new and self.w.interactive:   # a scripted run writes nothing of the user's
            self._write_site_file()
        self.w._update_actions()
        if self.w.sessions.is_modified():
            self.w.sessions.autosave()
        _settle_garbage_collector()
        self.w.mapReady.emit()

    def _on_run_failed(self, message: str) -> None:
        self._show_progress(False)
        self.w._update_actions()
        self.w.error(message)
        self.w.runFailed.emit(message)

    def _on_run_cancelled(self) -> None:
        self._show_progress(False)
        self.w._update_actions()
        self.w.statusBar().showMessage("Run cancelled; the current map and decisions are unchanged", 8000)
        self.w.runCancelled.emit()

    def _show_progress(self, on: bool) -> None:
        for w in (self.w.progress_bar, self.w.eta_label, self.w.cancel_button):
            w.setVisible(on)
        self.w.cancel_button.setEnabled(on)

    def _used_defaults(self, built: bool = True) -> dict:
        """What an unset threshold stands for, where that is known
        (``gui.model.run_plan.known_thresholds``); the others read "auto". ``built``: the map
        shown was built with the parameters of now (else its meta says nothing about them)."""
        from .model.run_plan import known_thresholds

        topomap = self.w.doc.topomap
        meta = topomap.meta if topomap is not None and built else None
        return known_thresholds(self.w.doc.params, meta, self._defaults)

    def _set_known_shifts(self, descs) -> None:
        self.w.frames.known_shifts = ({int(f): int(s) for f, s in zip(self.w.doc.descriptor_places(), descs.shifts)}
                                      if descs.meta.get("shift", True) else {})
        # A site's shifts are counted in its first recording's frame width (engine.site.combine).
        self.w.frames.known_width = int(descs.meta.get("frame_width", 0) or 0) if self.w.doc.site is not None else 0

    def _write_site_file(self) -> None:
        """The site file of recordings opened together, written once (their work hangs on it)."""
        site = self.w.doc.site
        try:
            self.w.doc.topomap.write_graphml(site.anchor, keep_rejected=True, keep_candidates=True)
        except (InputError, OSError) as exc:
            self.w.warn(f"The site file {site.anchor} could not be written ({getattr(exc, 'strerror', None) or exc}): "
                        "decisions are journaled, but reopening needs the recordings chosen together again")
            return
        site.new = False
        self.w._add_recent(str(site.anchor))

    def _params_edited(self, field: str, new: MapParams) -> None:
        old = self.w.doc.params
        if new == old:
            return
        self.w.undo_stack.push(ChangeParams(self._apply_params, old, new, field))

    def calibrate_thresholds(self) -> None:
        """Node and loop thresholds of the paper's methods from this recording (one undo step)."""
        from engine.calibrate import paper_thresholds

        if self.w.doc.descs is None:
            self.w.statusBar().showMessage("Run the recording first: thresholds come from its descriptors", 5000)
            return
        old = self.w.doc.params
        new = replace(old, **paper_thresholds(self.w.doc.descs.vectors, old.neighbor_node_num))
        if new != old:
            self.w.undo_stack.push(ChangeParams(self._apply_params, old, new, "thresholds"))

    def _apply_params(self, _old: MapParams, new: MapParams) -> None:
        """Rebuild the map with ``new`` (undo/redo and the panel both land here), as
        ``gui.model.run_plan.plan_change`` decides: re-map, describe again, or refuse."""
        self.w.doc.params = new
        if self.w.doc.input_path is None:   # set before any recording is open: where recordings start
            self._start_params = new
        self.w.params_panel.set_params(new, self._used_defaults(built=False))
        plan = run_plan.plan_change(new, self.w.doc.descs, self.w.doc.describe_settings,
                                    self.w.doc.descriptors_only(), self._preparing_run is not None)
        if plan.action == run_plan.DESCRIBE:
            self.start_run()
        elif plan.action == run_plan.REFUSE:
            self.w.warn(plan.message)
        elif plan.action == run_plan.REMAP:
            self._remap(new)

    def _remap(self, params: MapParams) -> None:
        """Build and prepare the map with ``params`` off the UI thread; the newest request wins."""
        from engine.pipeline import build_map

        descs, source, site = self.w.doc.descs, str(self.w.doc.input_path), self.w.doc.site
        self.w.statusBar().showMessage("Rebuilding the map…")
        if site is not None:   # each recording its own nodes and chain, as engine.site maps them
            from .model.site import site_remap

            records, named = (self.w.doc.topomap.graph.graph.get("sessions", ""),
                              str(self.w.doc.topomap.meta.get("source", "")))
            job = self.w.doc.remap_job(lambda: site_remap(descs, params, site, records, named))
        else:
            job = self.w.doc.remap_job(lambda: build_map(descs, params, source=source))
        self.w.remapper.submit(job, lambda prepared: self._remapped(descs, params, prepared),
                             lambda exc: self._remap_failed(descs, params, exc))

    def _remap_failed(self, descs, params: MapParams, exc: BaseException) -> None:
        if self.w.doc.descs is not descs or self.w.doc.params != params:
            return
        if isinstance(exc, InputError):
            self.w.warn(str(exc))
        else:
            self.w.error(f"unexpected error: {exc.__class__.__name__}: {exc}")

    def _remapped(self, descs, params: MapParams, prepared) -> None:
        if self.w.doc.descs is not descs or self.w.doc.params != params:
            return  # a new run or another parameter change came in meanwhile
        if not self.w.doc.is_current(prepared):
            self._remap(params)  # decided (or loaded poses) while it built: build with those
            return
        self.w.doc.install(prepared)
        self.w.params_panel.set_params(params, self._used_defaults())
        self.w.statusBar().showMessage(
            f"{self.w.doc.node_count()} nodes, {len(self.w.doc.loop_rows())} loops with the new parameters", 5000)
        self.w.mapReady.emit()

    def _request_similarity(self, *_args) -> None:
        """Compute the similarity matrix off the UI thread, when its tab is shown (20k nodes: seconds)."""
        if self.w.tabs.currentWidget() is not self.w.similarity_view or self.w.doc.similarity_ready():
            return
        job = self.w.doc.similarity_job()
        if job is None:
            return
        topomap = self.w.doc.topomap
        self.w.similarity_worker.submit(job, lambda sim: self.w.doc.set_similarity(topomap, sim),
                                      lambda exc: self.w.error(f"Similarity matrix failed: {exc}"))


def _settle_garbage_collector() -> None:
    """Collect once, then move everything alive to the collector's permanent generation.

    After a run the process holds millions of long-lived objects (torch, Qt, the engine's
    modules, the descriptors' metadata). Each full collection walked all of them: 200 ms
    with the GIL held, a stall of the window, every few re-maps of a 20k-node map
    (benchmarks/bench_ui_stall.py). Frozen, they are skipped; what is made later (the next
    maps) is collected as usual. One full collection per run is the price.
    """
    import gc

    gc.collect()
    gc.freeze()


def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    if seconds < 60:
        return f"{seconds} s"
    m, s = divmod(seconds, 60)
    if m < 60:
        return f"{m} min {s:02d} s"
    h, m = divmod(m, 60)
    return f"{h} h {m:02d} min"
