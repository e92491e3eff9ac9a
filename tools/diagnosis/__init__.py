"""Mismatch diagnosis (`adaptive-c3 diagnose`, `adaptive-c3 evaluate`): locate where a
recording and the model disagree, name the left-out effect from the effect library, fit it,
report it.

Wings: engine/ (locate, fit, evidence, report), backends/ (the models rolled out),
tasks/<task>/ (what a task adds), harness/ (concealed-effect data and hit rates). The
commands diagnose.py and evaluate.py sit on top and dispatch to the tasks.

May import tools/ shared modules (recording, progress, user_input), models/, scenarios/ and systems/."""
