"""Bag topic chooser: the image topic to map and, optionally, a ground-truth pose topic."""

from __future__ import annotations

from typing import Optional

from PySide6.QtWidgets import (QComboBox, QDialog, QDialogButtonBox, QFormLayout, QLabel, QVBoxLayout,
                               QWidget)

Topics = list[tuple[str, str, int]]   # (topic, msgtype, message count)


class BagTopicDialog(QDialog):
    def __init__(self, path: str, image_topics: Topics, pose_topics: Topics,
                 parent: Optional[QWidget] = None) -> None:
        super().__init__(parent)
        self.setWindowTitle("Open bag")
        intro = QLabel(f"<b>{path}</b><br>Choose the panorama topic to map and, if the bag has one, "
                       "the ground-truth pose topic used for evaluation (never for mapping).")
        intro.setWordWrap(True)
        self.image_topic = QComboBox()
        # The busiest image topic first: usually the camera stream.
        for topic, msgtype, count in sorted(image_topics, key=lambda t: -t[2]):
            self.image_topic.addItem(f"{topic}   ({msgtype.split('/')[-1]}, {count} messages)", topic)
        self.image_topic.setToolTip("Equirectangular (2:1) image topic")
        self.pose_topic = QComboBox()
        self.pose_topic.addItem("(none)", None)
        for topic, msgtype, count in pose_topics:
            self.pose_topic.addItem(f"{topic}   ({msgtype.split('/')[-1]}, {count} messages)", topic)
        if pose_topics:
            self.pose_topic.setCurrentIndex(1)
        self.pose_topic.setToolTip("Ground-truth poses (PoseStamped, Odometry, ...): evaluation only")
        buttons = QDialogButtonBox(QDialogButtonBox.Open | QDialogButtonBox.Cancel)
        buttons.accepted.connect(self.accept)
        buttons.rejected.connect(self.reject)
        form = QFormLayout()
        form.addRow("Image topic", self.image_topic)
        form.addRow("Pose topic", self.pose_topic)
        layout = QVBoxLayout(self)
        layout.addWidget(intro)
        layout.addLayout(form)
        layout.addWidget(buttons)
        self.resize(560, self.sizeHint().height())

    def chosen(self) -> tuple[Optional[str], Optional[str]]:
        return self.image_topic.currentData(), self.pose_topic.currentData()


def default_topics(image_topics: Topics, pose_topics: Topics) -> tuple[Optional[str], Optional[str]]:
    """What the dialog would preselect (used without a dialog, e.g. for screenshots)."""
    image = max(image_topics, key=lambda t: t[2])[0] if image_topics else None
    pose = pose_topics[0][0] if pose_topics else None
    return image, pose
