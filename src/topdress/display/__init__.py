"""The operator's screens: the web display (the paper's three screens, main, communication,
control, and the calibration wizards, with NiceGUI) and the text console with its typed
commands.

UI only: they render the `Snapshot` (topdress.view) and post the operator's commands; nothing
here imports the terminal. The web display is served from its own process
(`topdress.display.process`), so the control loop never waits on it. See docs/display.md.
"""
