"""Geography of a session: the outlet's position, as-applied exports (vector formats, ISO
11783-10 TaskData, CAN traces), the as-applied map, prescription maps and the field boundary.

Domain code: imports no UI. GDAL comes with pyogrio's wheel; no system GDAL is needed.
"""
