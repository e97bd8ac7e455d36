"""Maps: what the terminal reads (prescription maps, the field boundary, the outlet's position)
and what a session log becomes (as-applied exports in vector formats, ISO 11783-10 TaskData,
CAN traces, the as-applied map).

Domain code: imports no UI. GDAL comes with pyogrio's wheel; no system GDAL is needed.
"""
