/**
 * @file td_version.h
 * @brief Versions the ECU reports in EcuIdent: its own (the firmware, = the topdress release) and
 *        the protocol's (the VERSION line of protocol/topdress.dbc it was built with).
 *
 * tests/test_ecu_ident.py holds both to pyproject.toml and to the DBC.
 */
#ifndef TD_VERSION_H
#define TD_VERSION_H

#define TD_FW_VERSION_MAJOR 0u
#define TD_FW_VERSION_MINOR 1u
#define TD_FW_VERSION_PATCH 0u

#define TD_PROTO_VERSION_MAJOR 1u
#define TD_PROTO_VERSION_MINOR 1u

#endif /* TD_VERSION_H */
