#include "td_ibname.h"

#include "td_ib.h"

int td_ibname_encode(const td_ibname_t *n, uint64_t *out) {
    if (n == NULL || out == NULL || n->identity_number > 0x1FFFFFu ||
        n->manufacturer_code > 0x7FFu || n->ecu_instance > 7u || n->function_instance > 31u ||
        n->device_class > 127u || n->device_class_instance > 15u || n->industry_group > 7u ||
        n->self_configurable > 1u) {
        return TD_IB_E_ARG;
    }
    *out = (uint64_t)n->identity_number | ((uint64_t)n->manufacturer_code << 21) |
           ((uint64_t)n->ecu_instance << 32) | ((uint64_t)n->function_instance << 35) |
           ((uint64_t)n->function << 40) | ((uint64_t)n->device_class << 49) |
           ((uint64_t)n->device_class_instance << 56) | ((uint64_t)n->industry_group << 60) |
           ((uint64_t)n->self_configurable << 63);
    return TD_IB_OK;
}

void td_ibname_decode(uint64_t name, td_ibname_t *out) {
    if (out == NULL) {
        return;
    }
    out->identity_number = (uint32_t)(name & 0x1FFFFFu);
    out->manufacturer_code = (uint16_t)((name >> 21) & 0x7FFu);
    out->ecu_instance = (uint8_t)((name >> 32) & 7u);
    out->function_instance = (uint8_t)((name >> 35) & 31u);
    out->function = (uint8_t)((name >> 40) & 0xFFu);
    out->device_class = (uint8_t)((name >> 49) & 127u);
    out->device_class_instance = (uint8_t)((name >> 56) & 15u);
    out->industry_group = (uint8_t)((name >> 60) & 7u);
    out->self_configurable = (uint8_t)((name >> 63) & 1u);
}

uint32_t td_ibname_identity_from_uid(const uint8_t *uid, size_t len) {
    uint32_t h = 2166136261u;
    size_t i;
    if (uid == NULL) {
        return 0u;
    }
    for (i = 0u; i < len; i++) {
        h ^= uid[i];
        h *= 16777619u;
    }
    /* fold the upper 11 bits onto the lower 21 so every UID bit reaches the identity */
    return (h ^ (h >> 21)) & 0x1FFFFFu;
}

int td_ibname_topdress(uint16_t manufacturer_code, const uint8_t *uid, size_t uid_len,
                       td_ibname_t *out) {
    if (out == NULL || uid == NULL || uid_len == 0u || manufacturer_code > 0x7FFu) {
        return TD_IB_E_ARG;
    }
    out->identity_number = td_ibname_identity_from_uid(uid, uid_len);
    out->manufacturer_code = manufacturer_code;
    out->ecu_instance = 0u;
    out->function_instance = 0u;
    out->function = TD_IBNAME_FN_RATE_CONTROL;
    out->device_class = TD_IBNAME_DC_FERTILIZERS;
    out->device_class_instance = 0u;
    out->industry_group = TD_IBNAME_IG_AGRICULTURE;
    out->self_configurable = 1u;
    return TD_IB_OK;
}

void td_ibname_to_bytes(uint64_t name, uint8_t out[8]) {
    unsigned i;
    for (i = 0u; i < 8u; i++) {
        out[i] = (uint8_t)((name >> (8u * i)) & 0xFFu);
    }
}

uint64_t td_ibname_from_bytes(const uint8_t in[8]) {
    uint64_t v = 0u;
    unsigned i;
    for (i = 0u; i < 8u; i++) {
        v |= (uint64_t)in[i] << (8u * i);
    }
    return v;
}
