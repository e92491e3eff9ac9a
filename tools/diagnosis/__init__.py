"""Mismatch diagnosis (`adaptive-c3 diagnose`): locate where a recording and the model
disagree, name the left-out effect from the effect library, fit it, report it; the
concealed-effect harnesses and the SINDy-style baseline they compare against.

May import tools/ shared modules (recording, progress, user_input), models/, scenarios/ and systems/."""
