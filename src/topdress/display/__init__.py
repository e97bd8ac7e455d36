"""The operator display: the paper's three screens (main, communication, control) and the
calibration wizards as a web page served by the terminal (NiceGUI).

UI only: it renders the terminal's `Snapshot` and posts the operator's commands into the
terminal's inbox; no domain class imports it. It is served from its own process
(`topdress.display.process`), so the control loop never waits on it. See docs/display.md.
"""
