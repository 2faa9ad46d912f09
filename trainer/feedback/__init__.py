"""Where labels come from. The training loop talks to one `FeedbackSource` and never knows which."""

from trainer.feedback.base import FeedbackSource, LabelEvent, Segment, SourceRefused, StopRequested
from trainer.feedback.oracle import OracleFeedback

__all__ = ["FeedbackSource", "LabelEvent", "OracleFeedback", "Segment", "SourceRefused", "StopRequested"]
