"""The loop candidate table: a model over the map's loop arcs, sorting and a status filter.

Keyboard curation happens here: C/Y confirm, R/N reject, Backspace/U reset,
J/PgDn next, K/PgUp previous (the window's menu actions carry the same keys).
"""

from __future__ import annotations

import math
from typing import Any, Optional

from PySide6.QtCore import (QAbstractTableModel, QItemSelectionModel, QModelIndex,
                            QSortFilterProxyModel, Qt, Signal)
from PySide6.QtGui import QBrush, QColor, QKeyEvent
from PySide6.QtWidgets import (QAbstractItemView, QComboBox, QHBoxLayout, QHeaderView, QLabel, QSizePolicy,
                               QTableView, QVBoxLayout, QWidget)

from .document import Document, LoopKey, LoopRow
from .style import STATUS_COLORS

COLUMNS = ("Query", "Match", "Frames", "Sim.", "Win.", "Yaw°", "Status")
COLUMN_TIPS = (
    "Query: the earlier node of the pair",
    "Match: the later node of the pair (the loop candidate)",
    "Source frames of the two nodes",
    "Similarity: cosine of the two node descriptors",
    "Window count: matches in the best candidate window of the spatial consistency check ('ours')",
    "Relative heading between the two panoramas, in degrees",
    "auto = waiting for a decision; confirmed / rejected by you; manual = added by you",
)
STATUS_COLUMN = 6
FILTERS = (("All loops", None), ("Undecided (auto)", {"auto"}), ("Confirmed", {"confirmed"}),
           ("Rejected", {"rejected"}), ("Manual", {"manual"}), ("Kept (confirmed + manual)", {"confirmed", "manual"}))
KEY_ROLE = Qt.UserRole + 1

DECISION_KEYS = {Qt.Key_C: "confirmed", Qt.Key_Y: "confirmed", Qt.Key_R: "rejected",
                 Qt.Key_N: "rejected", Qt.Key_Backspace: "auto", Qt.Key_U: "auto"}
NEXT_KEYS = {Qt.Key_J: 1, Qt.Key_PageDown: 1, Qt.Key_K: -1, Qt.Key_PageUp: -1}


class LoopTableModel(QAbstractTableModel):
    def __init__(self, doc: Document) -> None:
        super().__init__()
        self.doc = doc
        self.rows: list[LoopRow] = []
        self._row_of: dict[LoopKey, int] = {}

    def refresh(self) -> None:
        """Re-read the loops; a status change only repaints, a new set resets."""
        rows = self._sorted(self.doc.loop_rows())
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
    sort_column = 0
    sort_order = Qt.AscendingOrder

    def _sort_value(self, r: LoopRow, col: int):
        yaw = r.yaw if r.yaw is not None else self.doc.estimated_yaws.get(r.key)
        return ((r.index_u, r.index_v), (r.index_v, r.index_u), r.key, _num(r.similarity), r.window_count,
                _num(yaw), r.status)[col]

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
            self.dataChanged.emit(self.index(row, 5), self.index(row, 5))

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
            if col == 5 and r.yaw is None and r.key in self.doc.estimated_yaws:
                return f"~{self.doc.estimated_yaws[r.key]:+.1f}"  # estimated from the images
            return self._display(r, col)
        if role == Qt.TextAlignmentRole and col != STATUS_COLUMN:
            return int(Qt.AlignRight | Qt.AlignVCenter)
        if role == Qt.BackgroundRole and col == STATUS_COLUMN:
            c = QColor(STATUS_COLORS.get(r.status, "#fff"))
            c.setAlpha(70)
            return QBrush(c)
        if role == Qt.ToolTipRole:
            label_u = self.doc.label_of_frame(r.key[0])
            label_v = self.doc.label_of_frame(r.key[1])
            names = f" ({label_u or '?'} ↔ {label_v or '?'})" if (label_u or label_v) else ""
            return f"{r.u} ↔ {r.v}{names}: similarity {r.similarity:.3f}, status {r.status}"
        return None

    @staticmethod
    def _display(r: LoopRow, col: int) -> str:
        if col == 0:
            return r.u
        if col == 1:
            return r.v
        if col == 2:
            return f"{r.key[0]} ↔ {r.key[1]}"
        if col == 3:
            return "—" if math.isnan(r.similarity) else f"{r.similarity:.3f}"
        if col == 4:
            return str(r.window_count) if r.window_count else "—"
        if col == 5:
            return "—" if r.yaw is None else f"{r.yaw:+.1f}"
        return r.status


def _num(x: Optional[float]) -> float:
    return -math.inf if x is None or math.isnan(x) else float(x)


class LoopFilterProxy(QSortFilterProxyModel):
    def __init__(self) -> None:
        super().__init__()
        self.statuses: Optional[set[str]] = None

    def sort(self, column: int, order=Qt.AscendingOrder) -> None:
        """Sort the source model (fast); this proxy keeps its order and only filters."""
        self.sourceModel().sort(column, order)

    def set_statuses(self, statuses: Optional[set[str]]) -> None:
        if hasattr(self, "beginFilterChange"):  # Qt >= 6.10; invalidateFilter is deprecated there
            self.beginFilterChange()
            self.statuses = statuses
            self.endFilterChange()
        else:
            self.statuses = statuses
            self.invalidateFilter()

    def refilter(self) -> None:
        self.set_statuses(self.statuses)

    def filterAcceptsRow(self, source_row: int, source_parent: QModelIndex) -> bool:
        if self.statuses is None:
            return True
        return self.sourceModel().rows[source_row].status in self.statuses


class LoopTableView(QTableView):
    """The table; curation keys are handled here when the window's shortcuts do not fire."""

    decide = Signal(str)
    stepRequested = Signal(int)

    def keyPressEvent(self, event: QKeyEvent) -> None:
        if event.modifiers() & (Qt.ControlModifier | Qt.AltModifier):
            return super().keyPressEvent(event)
        if event.key() in DECISION_KEYS:
            self.decide.emit(DECISION_KEYS[event.key()])
        elif event.key() in NEXT_KEYS:
            self.stepRequested.emit(NEXT_KEYS[event.key()])
        else:
            super().keyPressEvent(event)


class LoopTable(QWidget):
    """Filter bar, counts and the table; emits the selected loop key (or None)."""

    loopSelected = Signal(object)

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
        self.counts = QLabel()
        self.counts.setToolTip("Loops by status")
        # May be clipped in a narrow panel rather than widen the whole window.
        self.counts.setSizePolicy(QSizePolicy.Ignored, QSizePolicy.Preferred)
        self.counts.setAlignment(Qt.AlignRight | Qt.AlignVCenter)

        self.view = LoopTableView()
        self.view.setModel(self.proxy)
        self.view.setSortingEnabled(True)
        self.view.sortByColumn(0, Qt.AscendingOrder)
        self.view.setSelectionBehavior(QAbstractItemView.SelectRows)
        self.view.setSelectionMode(QAbstractItemView.SingleSelection)
        self.view.setAlternatingRowColors(True)
        self.view.verticalHeader().setVisible(False)
        self.view.verticalHeader().setDefaultSectionSize(22)
        self.view.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeToContents)
        self.view.horizontalHeader().setResizeContentsPrecision(100)  # look at 100 rows, not all
        self.view.horizontalHeader().setStretchLastSection(True)
        self.view.setToolTip("Loop candidates. C/Y confirm, R/N reject, Backspace/U reset, J/K next/previous")
        self.view.selectionModel().currentRowChanged.connect(self._current_changed)
        self.view.stepRequested.connect(self.step)

        bar = QHBoxLayout()
        bar.setContentsMargins(0, 0, 0, 0)
        bar.addWidget(QLabel("Show:"))
        bar.addWidget(self.filter)
        bar.addWidget(self.counts, 1)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(bar)
        layout.addWidget(self.view, 1)

        self._last_key: Optional[LoopKey] = None
        doc.mapReplaced.connect(self.refresh)
        doc.loopsChanged.connect(self.refresh)
        doc.labelsChanged.connect(self.refresh)
        doc.estimatedYaw.connect(self.model.yaw_changed)

    # -- selection -------------------------------------------------------------------
    def selected_key(self) -> Optional[LoopKey]:
        index = self.view.selectionModel().currentIndex()
        if not index.isValid() or not self.view.selectionModel().isRowSelected(index.row(), QModelIndex()):
            return None
        return self.proxy.data(self.proxy.index(index.row(), 0), KEY_ROLE)

    def select_key(self, key: Optional[LoopKey]) -> bool:
        """Select ``key``'s row (clearing the filter if it hides it); False if there is no such loop."""
        if key is None:
            self.view.clearSelection()
            self.view.setCurrentIndex(QModelIndex())
            return False
        row = self.model.row_of(tuple(key))
        if row is None:
            return False
        proxy_index = self.proxy.mapFromSource(self.model.index(row, 0))
        if not proxy_index.isValid():
            self.filter.setCurrentIndex(0)
            proxy_index = self.proxy.mapFromSource(self.model.index(row, 0))
        self._select_proxy_row(proxy_index.row())
        return True

    def step(self, delta: int) -> None:
        """Select the next (delta > 0) or previous visible row."""
        n = self.proxy.rowCount()
        if n == 0:
            return
        current = self.view.selectionModel().currentIndex()
        row = current.row() if current.isValid() else (-1 if delta > 0 else n)
        self._select_proxy_row(min(max(row + delta, 0), n - 1))

    def key_after(self, key: LoopKey) -> Optional[LoopKey]:
        """The loop shown below ``key`` (or above it when it is the last), for auto-advance."""
        row = self.model.row_of(key)
        if row is None:
            return None
        prow = self.proxy.mapFromSource(self.model.index(row, 0)).row()
        for r in (prow + 1, prow - 1):
            if 0 <= r < self.proxy.rowCount():
                return self.proxy.data(self.proxy.index(r, 0), KEY_ROLE)
        return None

    def _select_proxy_row(self, row: int) -> None:
        index = self.proxy.index(row, 0)
        self.view.selectionModel().setCurrentIndex(
            index, QItemSelectionModel.ClearAndSelect | QItemSelectionModel.Rows)
        self.view.scrollTo(index)

    def _current_changed(self, current: QModelIndex, _previous: QModelIndex) -> None:
        key = self.proxy.data(self.proxy.index(current.row(), 0), KEY_ROLE) if current.isValid() else None
        self._last_key = key
        self.loopSelected.emit(key)

    # -- refresh ---------------------------------------------------------------------
    def refresh(self) -> None:
        key = self.selected_key() or self._last_key
        self.model.refresh()
        if self.proxy.statuses is not None:
            self.proxy.refilter()  # statuses changed: rows may enter or leave the filter
        self._update_counts()
        if key is not None and self.model.row_of(key) is not None:
            row = self.proxy.mapFromSource(self.model.index(self.model.row_of(key), 0)).row()
            if row >= 0:
                self.view.selectionModel().blockSignals(True)
                self._select_proxy_row(row)
                self.view.selectionModel().blockSignals(False)

    def _filter_changed(self) -> None:
        key = self.selected_key()
        self.proxy.set_statuses(FILTERS[max(self.filter.currentIndex(), 0)][1])
        row = self.model.row_of(key) if key is not None else None
        if row is not None and self.proxy.mapFromSource(self.model.index(row, 0)).isValid():
            self.select_key(key)  # still shown: keep it selected (a hidden one is not forced back)

    def _update_counts(self) -> None:
        counts = {s: 0 for s in STATUS_COLORS}
        for r in self.model.rows:
            counts[r.status] = counts.get(r.status, 0) + 1
        parts = [f"<span style='color:{STATUS_COLORS[s]}'>■</span>&nbsp;{counts[s]}&nbsp;{s}" for s in STATUS_COLORS]
        self.counts.setText(" &nbsp; ".join(parts))
