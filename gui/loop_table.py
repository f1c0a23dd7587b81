"""The review queue as a table: every loop ranked by evidence, filters, counts, multi-select.

The ranking, the counts and the decisions live in the Qt-free ``gui.model.queue``;
this widget shows them. Rows can be multi-selected (Shift/Ctrl+click, Ctrl+A) and a
decision key applies to every selected row, as one undo step. The keys themselves
are the window's actions (``gui.model.keys``); the table takes no letters of its own,
and Tab leaves it (no focus trap).

A site (several recordings): a third filter chooses the pair of recordings the loops join
("All recordings", "A × A", "A × B", ... with their counts; ``ReviewQueue.pair_choices``),
and the Query and Match cells take the colour of their node's recording.
"""

from __future__ import annotations

import math
from typing import Any, Optional

from PySide6.QtCore import (QAbstractTableModel, QItemSelection, QItemSelectionModel, QModelIndex,
                            QSortFilterProxyModel, Qt, Signal)
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import (QAbstractItemView, QComboBox, QHBoxLayout, QHeaderView, QLabel, QSizePolicy,
                               QTableView, QVBoxLayout, QWidget)

from .document import Document, LoopKey, LoopRow
from .model.queue import KINDS, ReviewQueue, in_pair, rank_key
from .style import STATUS_COLORS, recording_color

COLUMNS = ("#", "Status", "Conf.", "Query", "Match", "Score", "Inl.", "Sim.", "Yaw°")
COLUMN_TIPS = (
    "Rank by evidence: the engine's confidence (else calibrated score, else similarity), then inliers",
    "candidate = found, waiting for you; auto = accepted automatically; confirmed / rejected by you; "
    "manual = added by you",
    "Confidence: the engine's ranking of the loop for review (what the queue is ordered by), where given",
    "Query: the earlier node of the pair (source frame in the tooltip)",
    "Match: the later node of the pair",
    "Calibrated descriptor score (standard deviations above the recording's background), where known",
    "Geometric inliers (and their ratio in the tooltip), where verified",
    "Similarity: cosine of the two node descriptors",
    "Relative heading between the two panoramas, in degrees (~: estimated from the images)",
)
(RANK_COLUMN, STATUS_COLUMN, CONFIDENCE_COLUMN, QUERY_COLUMN, MATCH_COLUMN, SCORE_COLUMN, INLIERS_COLUMN,
 SIMILARITY_COLUMN, YAW_COLUMN) = range(len(COLUMNS))
FILTERS = (("All loops", None), ("Undecided (candidate + auto)", {"candidate", "auto"}),
           ("Candidates", {"candidate"}), ("Auto", {"auto"}), ("Confirmed", {"confirmed"}),
           ("Rejected", {"rejected"}), ("Manual", {"manual"}), ("Kept (auto + confirmed + manual)",
                                                                  {"auto", "confirmed", "manual"}))
KIND_FILTERS = (("Any kind", None),) + tuple((f"Found as {k}", {k}) for k in KINDS)
KEY_ROLE = Qt.UserRole + 1
FALLBACK_COLOR = "#95a5a6"


def status_color(status: str) -> str:
    return STATUS_COLORS.get(status, FALLBACK_COLOR)


class LoopTableModel(QAbstractTableModel):
    def __init__(self, doc: Document) -> None:
        super().__init__()
        self.doc = doc
        self.rows: list[LoopRow] = []
        self.rank: dict[LoopKey, int] = {}
        self._row_of: dict[LoopKey, int] = {}

    def refresh(self) -> None:
        """Re-read the loops; a status change only repaints, a new set resets."""
        source = self.doc.loop_rows()
        self.rank = {r.key: i + 1 for i, r in enumerate(sorted(source, key=rank_key))}
        rows = self._sorted(source)
        if [r.key for r in rows] == [r.key for r in self.rows]:
            self.rows = rows
            if rows:
                self.dataChanged.emit(self.index(0, 0), self.index(len(rows) - 1, len(COLUMNS) - 1))
            return
        self.beginResetModel()
        self.rows = rows
        self._row_of = {r.key: i for i, r in enumerate(rows)}
        self.endResetModel()

    # Sorting happens here, in Python's sort over plain values, not in the proxy: a
    # proxy sort calls data() through Qt for every comparison (seconds for 10^4 loops).
    sort_column = RANK_COLUMN
    sort_order = Qt.AscendingOrder

    def _sort_value(self, r: LoopRow, col: int):
        yaw = r.yaw if r.yaw is not None else self.doc.estimated_yaws.get(r.key)
        if col == RANK_COLUMN:
            return self.rank.get(r.key, 0)
        return (None, r.status, _num(r.confidence), (r.index_u, r.index_v), (r.index_v, r.index_u), _num(r.score),
                -1 if r.inliers is None else r.inliers, _num(r.similarity), _num(yaw))[col]

    def _sorted(self, rows: list[LoopRow]) -> list[LoopRow]:
        return sorted(rows, key=lambda r: self._sort_value(r, self.sort_column),
                      reverse=self.sort_order == Qt.DescendingOrder)

    def sort(self, column: int, order=Qt.AscendingOrder) -> None:
        self.sort_column, self.sort_order = column, order
        self.layoutAboutToBeChanged.emit()
        old = self.persistentIndexList()
        old_keys = [self.rows[i.row()].key for i in old]
        self.rows = self._sorted(self.rows)
        self._row_of = {r.key: i for i, r in enumerate(self.rows)}
        self.changePersistentIndexList(old, [self.index(self._row_of[k], i.column()) for k, i in zip(old_keys, old)])
        self.layoutChanged.emit()

    def yaw_changed(self, key: LoopKey) -> None:
        row = self._row_of.get(key)
        if row is not None:
            self.dataChanged.emit(self.index(row, YAW_COLUMN), self.index(row, YAW_COLUMN))

    def row_of(self, key: LoopKey) -> Optional[int]:
        return self._row_of.get(key)

    def rowCount(self, parent: QModelIndex = QModelIndex()) -> int:
        return 0 if parent.isValid() else len(self.rows)

    def columnCount(self, parent: QModelIndex = QModelIndex()) -> int:
        return 0 if parent.isValid() else len(COLUMNS)

    def headerData(self, section: int, orientation, role: int = Qt.DisplayRole) -> Any:
        if orientation == Qt.Horizontal:
            if role == Qt.DisplayRole:
                return COLUMNS[section]
            if role == Qt.ToolTipRole:
                return COLUMN_TIPS[section]
        return None

    def data(self, index: QModelIndex, role: int = Qt.DisplayRole) -> Any:
        if not index.isValid():
            return None
        r = self.rows[index.row()]
        col = index.column()
        if role == KEY_ROLE:
            return r.key
        if role == Qt.DisplayRole:
            if col == YAW_COLUMN and r.yaw is None and r.key in self.doc.estimated_yaws:
                return f"~{self.doc.estimated_yaws[r.key]:+.1f}"  # estimated from the images
            return self._display(r, col)
        if role == Qt.TextAlignmentRole and col != STATUS_COLUMN:
            return int(Qt.AlignRight | Qt.AlignVCenter)
        if role == Qt.BackgroundRole and col == STATUS_COLUMN:
            c = QColor(status_color(r.status))
            c.setAlpha(70)
            return QBrush(c)
        if role == Qt.BackgroundRole and col in (QUERY_COLUMN, MATCH_COLUMN) and r.sessions and self.doc.site:
            c = QColor(recording_color(self.doc.site.index(r.sessions[col == MATCH_COLUMN])))
            c.setAlpha(90)
            return QBrush(c)
        if role == Qt.ToolTipRole:
            return self._tooltip(r)
        return None

    def _display(self, r: LoopRow, col: int) -> str:
        if col == RANK_COLUMN:
            return str(self.rank.get(r.key, ""))
        if col == STATUS_COLUMN:
            return r.status
        if col == CONFIDENCE_COLUMN:
            return "—" if r.confidence is None else f"{r.confidence:.2f}"
        if col == QUERY_COLUMN:
            return r.u
        if col == MATCH_COLUMN:
            return r.v
        if col == SCORE_COLUMN:
            return "—" if r.score is None else f"{r.score:.3f}"
        if col == INLIERS_COLUMN:
            return "—" if r.inliers is None else str(r.inliers)
        if col == SIMILARITY_COLUMN:
            return "—" if math.isnan(r.similarity) else f"{r.similarity:.3f}"
        return "—" if r.yaw is None else f"{r.yaw:+.1f}"

    def _tooltip(self, r: LoopRow) -> str:
        label_u = self.doc.label_of_frame(r.key[0])
        label_v = self.doc.label_of_frame(r.key[1])
        names = f" ({label_u or '?'} ↔ {label_v or '?'})" if (label_u or label_v) else ""
        where = (f"frames {r.key[0]} ↔ {r.key[1]}" if self.doc.site is None else
                 f"{self.doc.place_text(r.key[0])} ↔ {self.doc.place_text(r.key[1])}")
        parts = [f"{r.u} ↔ {r.v}{names}, {where}",
                 f"status {r.status} (found as {r.tier})", f"similarity {r.similarity:.3f}"]
        if r.score is not None:
            parts.append(f"score {r.score:.3f}")
        if r.inliers is not None:
            ratio = f" ({100 * r.inlier_ratio:.0f} %)" if r.inlier_ratio is not None else ""
            parts.append(f"{r.inliers} inliers{ratio}")
        if r.matches is not None:
            parts.append(f"{r.matches} feature matches")
        if r.support is not None:
            parts.append(f"sequence support {r.support:.2f}")
        if r.direction is not None:
            parts.append("travelled the same way" if r.direction > 0 else "travelled the other way")
        if r.confidence is not None:
            parts.append(f"confidence {r.confidence:.3f} (the rank)")
        if r.window_count:
            parts.append(f"window count {r.window_count}")
        return "\n".join(parts)


def _num(x: Optional[float]) -> float:
    return -math.inf if x is None or math.isnan(x) else float(x)


class LoopFilterProxy(QSortFilterProxyModel):
    def __init__(self) -> None:
        super().__init__()
        self.statuses: Optional[set[str]] = None
        self.kinds: Optional[set[str]] = None
        self.pair: Optional[tuple[str, str]] = None   # a site: only loops between these recordings

    def sort(self, column: int, order=Qt.AscendingOrder) -> None:
        """Sort the source model (fast); this proxy keeps its order and only filters."""
        self.sourceModel().sort(column, order)

    def set_filter(self, statuses: Optional[set[str]], kinds: Optional[set[str]] = None,
                   pair: Optional[tuple[str, str]] = None) -> None:
        if hasattr(self, "beginFilterChange"):  # Qt >= 6.10; invalidateFilter is deprecated there
            self.beginFilterChange()
            self.statuses, self.kinds, self.pair = statuses, kinds, pair
            self.endFilterChange()
        else:
            self.statuses, self.kinds, self.pair = statuses, kinds, pair
            self.invalidateFilter()

    def set_statuses(self, statuses: Optional[set[str]]) -> None:
        self.set_filter(statuses, self.kinds, self.pair)

    def refilter(self) -> None:
        self.set_filter(self.statuses, self.kinds, self.pair)

    def filterAcceptsRow(self, source_row: int, source_parent: QModelIndex) -> bool:
        row = self.sourceModel().rows[source_row]
        return ((self.statuses is None or row.status in self.statuses)
                and (self.kinds is None or row.tier in self.kinds) and in_pair(row, self.pair))


class LoopTable(QWidget):
    """Filter bar, counts and the table; emits the current loop key (or None)."""

    loopSelected = Signal(object)
    selectionChanged = Signal()

    def __init__(self, doc: Document, parent: Optional[QWidget] = None) -> None:
        super().__init__(parent)
        self.doc = doc
        self.model = LoopTableModel(doc)
        self.proxy = LoopFilterProxy()
        self.proxy.setSourceModel(self.model)

        self.filter = QComboBox()
        self.filter.setToolTip("Show only loops with these statuses")
        for text, _statuses in FILTERS:
            self.filter.addItem(text)
        self.filter.currentIndexChanged.connect(self._filter_changed)
        self.kind_filter = QComboBox()
        self.kind_filter.setToolTip("Show only loops that detection found as this kind")
        for text, _kinds in KIND_FILTERS:
            self.kind_filter.addItem(text)
        self.kind_filter.currentIndexChanged.connect(self._filter_changed)
        self.pair_filter = QComboBox()
        self.pair_filter.setToolTip("A site: show only the loops between these two recordings "
                                    "(loops in all; undecided in brackets)")
        self.pair_filter.currentIndexChanged.connect(self._filter_changed)
        self.pair_label = QLabel("Recordings:")
        self.counts = QLabel()
        self.counts.setToolTip("Loops by status (and, below, by the kind detection found them as)")
        # May be clipped in a narrow panel rather than widen the whole window.
        self.counts.setSizePolicy(QSizePolicy.Ignored, QSizePolicy.Preferred)
        self.counts.setWordWrap(True)

        self.view = QTableView()
        self.view.setModel(self.proxy)
        self.view.setSortingEnabled(True)
        self.view.sortByColumn(RANK_COLUMN, Qt.AscendingOrder)
        self.view.setSelectionBehavior(QAbstractItemView.SelectRows)
        self.view.setSelectionMode(QAbstractItemView.ExtendedSelection)
        self.view.setTabKeyNavigation(False)  # Tab moves on to the next widget (issue 14, defect 6)
        self.view.setAlternatingRowColors(True)
        self.view.verticalHeader().setVisible(False)
        # Compact rows: a long review needs many rows on screen (issue 43, defect 7).
        self.view.verticalHeader().setDefaultSectionSize(self.view.fontMetrics().height() + 6)
        self.view.verticalHeader().setMinimumSectionSize(self.view.fontMetrics().height() + 2)
        self.view.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeToContents)
        self.view.horizontalHeader().setResizeContentsPrecision(100)  # look at 100 rows, not all
        # No column stretches: a stretched last column (Yaw) took half the table's width.
        self.view.horizontalHeader().setStretchLastSection(False)
        self.view.setToolTip("The review queue, best evidence first. Select one or many rows (Shift/Ctrl+click, "
                             "Ctrl+A), then C confirm, R reject; F: next undecided. Help ▸ Keyboard shortcuts")
        self.view.selectionModel().currentRowChanged.connect(self._current_changed)
        self.view.selectionModel().selectionChanged.connect(lambda *_: self.selectionChanged.emit())

        bar = QHBoxLayout()
        bar.setContentsMargins(0, 0, 0, 0)
        bar.addWidget(QLabel("Show:"))
        bar.addWidget(self.filter, 1)
        bar.addWidget(self.kind_filter, 1)
        pair_bar = QHBoxLayout()   # a row of its own: one more combo would squeeze a 1280-px column
        pair_bar.setContentsMargins(0, 0, 0, 0)
        pair_bar.addWidget(self.pair_label)
        pair_bar.addWidget(self.pair_filter, 1)
        for w in (self.pair_label, self.pair_filter):
            w.setVisible(False)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(bar)
        layout.addLayout(pair_bar)
        layout.addWidget(self.counts)
        layout.addWidget(self.view, 1)

        self._last_key: Optional[LoopKey] = None
        self._emitted: Optional[LoopKey] = None   # the key the views were last told of
        doc.mapReplaced.connect(self.refresh)
        doc.loopsChanged.connect(self.refresh)
        doc.labelsChanged.connect(self.refresh)
        doc.estimatedYaw.connect(self.model.yaw_changed)

    # -- selection -------------------------------------------------------------------
    def selected_key(self) -> Optional[LoopKey]:
        """The current row's loop, if it is selected."""
        index = self.view.selectionModel().currentIndex()
        if not index.isValid() or not self.view.selectionModel().isRowSelected(index.row(), QModelIndex()):
            return None
        return self.proxy.data(self.proxy.index(index.row(), 0), KEY_ROLE)

    def selected_keys(self) -> list[LoopKey]:
        """Every selected (and therefore shown) loop, in the order shown."""
        rows = sorted(i.row() for i in self.view.selectionModel().selectedRows())
        return [self.proxy.data(self.proxy.index(r, 0), KEY_ROLE) for r in rows]

    def visible_keys(self) -> list[LoopKey]:
        """The loops shown, in the order shown."""
        return [self.proxy.data(self.proxy.index(r, 0), KEY_ROLE) for r in range(self.proxy.rowCount())]

    def select_key(self, key: Optional[LoopKey]) -> bool:
        """Select ``key``'s row (clearing the filter if it hides it); False if there is no such loop."""
        if key is None:
            self.view.clearSelection()
            self.view.setCurrentIndex(QModelIndex())
            self._last_key = self._emitted = None   # nothing of it may come back on the next map
            return False
        row = self.model.row_of(tuple(key))
        if row is None:
            return False
        proxy_index = self.proxy.mapFromSource(self.model.index(row, 0))
        if not proxy_index.isValid():
            self.filter.setCurrentIndex(0)
            self.kind_filter.setCurrentIndex(0)
            if self.pair_filter.count():
                self.pair_filter.setCurrentIndex(0)
            proxy_index = self.proxy.mapFromSource(self.model.index(row, 0))
        self._select_proxy_row(proxy_index.row())
        return True

    def select_keys(self, keys: list[LoopKey]) -> None:
        """Select exactly these loops among those shown (hidden ones are not forced into view)."""
        rows = []
        for key in keys:
            row = self.model.row_of(tuple(key))
            if row is not None:
                index = self.proxy.mapFromSource(self.model.index(row, 0))
                if index.isValid():
                    rows.append(index.row())
        if not rows:
            self.select_key(None)
            return
        if len(rows) == 1:
            self._select_proxy_row(rows[0])
            return
        selection = QItemSelection()
        for r in rows:
            selection.select(self.proxy.index(r, 0), self.proxy.index(r, len(COLUMNS) - 1))
        sm = self.view.selectionModel()
        # The current row stays where the user left it when it is still selected (issue 43,
        # defect 8: after a bulk decision it jumped back to the first selected row).
        current = sm.currentIndex().row() if sm.currentIndex().isValid() else -1
        sm.setCurrentIndex(self.proxy.index(current if current in rows else rows[0], 0), QItemSelectionModel.NoUpdate)
        sm.select(selection, QItemSelectionModel.ClearAndSelect)

    def step(self, delta: int) -> None:
        """Select the next (delta > 0) or previous shown row; both ends wrap around (J and K alike)."""
        n = self.proxy.rowCount()
        if n == 0:
            return
        current = self.view.selectionModel().currentIndex()
        row = current.row() if current.isValid() else (-1 if delta > 0 else n)
        self._select_proxy_row((row + delta) % n)

    def _select_proxy_row(self, row: int) -> None:
        index = self.proxy.index(row, 0)
        self.view.selectionModel().setCurrentIndex(
            index, QItemSelectionModel.ClearAndSelect | QItemSelectionModel.Rows)
        self.view.scrollTo(index)
        self._announce()

    def _announce(self) -> None:
        """Tell the views the selected loop when they were not told yet: selecting the row that
        is already current emits nothing from Qt (issue 43, defect 5: a session restored the row
        of the loop last shown, and the pair view stayed empty)."""
        if self.view.selectionModel().signalsBlocked():
            return
        key = self.selected_key()
        if key is not None and key != self._emitted:
            self._emitted = key
            self.loopSelected.emit(key)

    def _current_changed(self, current: QModelIndex, _previous: QModelIndex) -> None:
        key = self.proxy.data(self.proxy.index(current.row(), 0), KEY_ROLE) if current.isValid() else None
        self._last_key = self._emitted = key
        self.loopSelected.emit(key)

    # -- refresh ---------------------------------------------------------------------
    def refresh(self) -> None:
        keys = self.selected_keys()
        current = self.selected_key() or self._last_key
        self.model.refresh()
        pair = self.proxy.pair
        self._update_pairs()
        if (self.proxy.statuses is not None or self.proxy.kinds is not None or self.proxy.pair is not None
                or pair != self.proxy.pair):
            self.proxy.refilter()  # statuses changed: rows may enter or leave the filter
        self._update_counts()
        sm = self.view.selectionModel()
        sm.blockSignals(True)
        try:
            if len(keys) > 1:
                self.select_keys(keys)
            elif current is not None and self.model.row_of(current) is not None:
                row = self.proxy.mapFromSource(self.model.index(self.model.row_of(current), 0)).row()
                if row >= 0:
                    self._select_proxy_row(row)
        finally:
            sm.blockSignals(False)
        self._announce()   # a row selected again on a new map: the views show its loop

    def _filter_changed(self) -> None:
        keys = self.selected_keys()
        self.proxy.set_filter(FILTERS[max(self.filter.currentIndex(), 0)][1],
                              KIND_FILTERS[max(self.kind_filter.currentIndex(), 0)][1], self.pair_filter.currentData())
        if keys:
            self.select_keys(keys)  # those still shown stay selected (hidden ones are not forced back)

    def set_pair(self, pair: Optional[tuple[str, str]]) -> bool:
        """Show only the loops between the recordings of ``pair`` (None: all); False if the site has no such pair."""
        for i in range(self.pair_filter.count()):
            data = self.pair_filter.itemData(i)
            if (data is None and pair is None) or (data is not None and pair is not None
                                                    and sorted(data) == sorted(pair)):
                self.pair_filter.setCurrentIndex(i)
                return True
        return False

    def _update_pairs(self) -> None:
        """The pair filter's choices and counts (a site); hidden for one recording."""
        choices = ReviewQueue(self.doc).pair_choices()
        for w in (self.pair_label, self.pair_filter):
            w.setVisible(bool(choices))
        texts = [f"{text}: {n} loops" + (f" ({u} undecided)" if u else "") for text, _p, n, u in choices]
        pairs = [p for _t, p, _n, _u in choices]
        self.pair_filter.blockSignals(True)
        try:
            if pairs == [self.pair_filter.itemData(i) for i in range(self.pair_filter.count())]:
                for i, text in enumerate(texts):   # the same pairs: the counts only
                    self.pair_filter.setItemText(i, text)
            else:
                current = self.pair_filter.currentData()
                self.pair_filter.clear()
                for text, pair in zip(texts, pairs):
                    self.pair_filter.addItem(text, pair)
                at = pairs.index(current) if current in pairs else 0
                self.pair_filter.setCurrentIndex(at if pairs else -1)
                self.proxy.pair = self.pair_filter.currentData()
        finally:
            self.pair_filter.blockSignals(False)

    def _update_counts(self) -> None:
        counts = ReviewQueue(self.doc).counts()
        status, kind = counts["status"], counts["kind"]
        parts = [f"<span style='color:{status_color(s)}'>■</span>&nbsp;{n}&nbsp;{s}"
                 for s, n in status.items() if n or s in ("auto", "confirmed", "rejected")]
        found = ", ".join(f"{n} {k}" for k, n in kind.items() if n)
        self.counts.setText(" &nbsp; ".join(parts) + f" &nbsp;·&nbsp; <b>{counts['undecided']['undecided']} undecided</b>"
                            + (f" &nbsp;·&nbsp; found as: {found}" if found else ""))
