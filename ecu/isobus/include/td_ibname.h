/**
 * @file td_ibname.h
 * @brief The ISO 11783-5 / J1939-81 NAME: 64 bits that identify a control function and decide
 *        address-claim contests (the numerically lower NAME wins).
 *
 * Bit layout (bit 0 = least significant, sent first as little-endian bytes):
 *   0..20 identity number, 21..31 manufacturer code, 32..34 ECU instance, 35..39 function
 *   instance, 40..47 function, 48 reserved (0), 49..55 device class, 56..59 device class
 *   instance, 60..62 industry group, 63 self-configurable address.
 */
#ifndef TD_IBNAME_H
#define TD_IBNAME_H

#include <stddef.h>
#include <stdint.h>

#define TD_IBNAME_IG_AGRICULTURE 2u      /**< industry group 2: agricultural and forestry */
#define TD_IBNAME_DC_FERTILIZERS 5u      /**< device class 5 of industry group 2: fertilizers */
#define TD_IBNAME_FN_RATE_CONTROL 128u   /**< function 128 of device class 5: Fertilize Rate Control */

/** The fields of a NAME, each in its own range (checked by td_ibname_encode). */
typedef struct {
    uint32_t identity_number;    /**< 0..2^21-1, unique per manufacturer */
    uint16_t manufacturer_code;  /**< 0..2047, assigned by the ISOBUS registration */
    uint8_t ecu_instance;        /**< 0..7 */
    uint8_t function_instance;   /**< 0..31 */
    uint8_t function;            /**< 0..255 */
    uint8_t device_class;        /**< 0..127 ("vehicle system" in J1939) */
    uint8_t device_class_instance; /**< 0..15 */
    uint8_t industry_group;      /**< 0..7 */
    uint8_t self_configurable;   /**< 1 = may claim an address other than its preferred one */
} td_ibname_t;

/** Packs the fields into `*out`. TD_IB_E_ARG when a field is out of its range. */
int td_ibname_encode(const td_ibname_t *n, uint64_t *out);
/** Unpacks a NAME. */
void td_ibname_decode(uint64_t name, td_ibname_t *out);
/** Identity number (21 bits) from a board's unique ID (e.g. the STM32's 96-bit UID): a FNV-1a
 *  hash folded to 21 bits, so two boards of one batch differ with high probability. */
uint32_t td_ibname_identity_from_uid(const uint8_t *uid, size_t len);
/** The topdress implement's NAME: industry group 2, fertilizer device class, rate control
 *  function, self-configurable, the given manufacturer code and identity number from `uid`. */
int td_ibname_topdress(uint16_t manufacturer_code, const uint8_t *uid, size_t uid_len,
                       td_ibname_t *out);
/** NAME as the 8 bytes of an Address Claimed message (little-endian). */
void td_ibname_to_bytes(uint64_t name, uint8_t out[8]);
uint64_t td_ibname_from_bytes(const uint8_t in[8]);

#endif
