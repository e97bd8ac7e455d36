/* Generated from protocol/topdress.dbc by scripts/gen_prop.py: never edit by hand. */
#ifndef TD_PROP_GEN_H
#define TD_PROP_GEN_H

/* The frames of the paper's bus on an ISOBUS: X(frame, fixed 29-bit identifier, ISOBUS
 * PGN, priority, 1 sent by the ECU / 0 by the terminal). */
#define TD_PROP_COUNT 15u
#define TD_PROP_TABLE(X) \
    X(EcuStatus, 0x185C6465u, 0x0FF5Cu, 6u, 1u) \
    X(EcuDiag, 0x185D6465u, 0x0FF5Du, 6u, 1u) \
    X(EcuSpeeds, 0x185E6465u, 0x0FF5Eu, 6u, 1u) \
    X(EcuTargets, 0x185F6465u, 0x0FF5Fu, 6u, 1u) \
    X(PcParamSet, 0x0A606465u, 0x0EF00u, 2u, 0u) \
    X(EcuParamAck, 0x18616465u, 0x0EF00u, 6u, 1u) \
    X(PcCalCommand, 0x0A646465u, 0x1EF00u, 2u, 0u) \
    X(EcuCalStatus, 0x18656465u, 0x0FF65u, 6u, 1u) \
    X(PcGnssTime, 0x0A626465u, 0x0FF62u, 2u, 0u) \
    X(EcuFused, 0x18636465u, 0x0FF63u, 6u, 1u) \
    X(EcuFusedAux, 0x18666465u, 0x0FF66u, 6u, 1u) \
    X(EcuGnssLag, 0x18696465u, 0x0FF69u, 6u, 1u) \
    X(EcuIdent, 0x18676465u, 0x0FF67u, 6u, 1u) \
    X(EcuCanHealth, 0x186A6465u, 0x0FF6Au, 6u, 1u) \
    X(EcuFaultRecord, 0x186B6465u, 0x0FF6Bu, 6u, 1u) \
    /* end */

#endif
