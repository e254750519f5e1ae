// SDS Arduino line protocol, version 1 (sds_arduino/protocol.py is the reference):
//   $SDS1,<seq>,<t_us>,<KIND>,<value>,...*<XX>\r\n
// XX: XOR of every byte between '$' and '*', two upper-case hex digits (as NMEA).
// Plain C++ without Arduino headers, so the host's compiler can test it against Python.
#ifndef SDS_PROTOCOL_H
#define SDS_PROTOCOL_H

#include <stddef.h>
#include <stdint.h>

#define SDS_MAX_LINE 96  // the bridge drops longer lines

// Appends the decimal digits of `value` at out[pos]; returns the new position.
static size_t sds_put_unsigned(char *out, size_t pos, uint32_t value) {
  char digits[10];
  size_t count = 0;
  do {
    digits[count++] = (char)('0' + value % 10u);
    value /= 10u;
  } while (value != 0u);
  while (count > 0u) out[pos++] = digits[--count];
  return pos;
}

static size_t sds_put_signed(char *out, size_t pos, int32_t value) {
  if (value < 0) {
    out[pos++] = '-';
    return sds_put_unsigned(out, pos, (uint32_t)(-(int64_t)value));
  }
  return sds_put_unsigned(out, pos, (uint32_t)value);
}

// Writes one record's line (with CR LF and a terminating NUL) into `out`, which must hold
// SDS_MAX_LINE + 1 chars; returns its length, 0 if it would not fit.
static size_t sds_format(char *out, uint32_t seq, uint32_t t_us, const char *kind,
                         const int32_t *values, uint8_t count) {
  // At most 4 values and a 3-letter kind: the longest line has 84 chars.
  if (count > 4u) return 0u;
  size_t pos = 0;
  out[pos++] = '$';
  const char *header = "SDS1,";
  while (*header) out[pos++] = *header++;
  pos = sds_put_unsigned(out, pos, seq);
  out[pos++] = ',';
  pos = sds_put_unsigned(out, pos, t_us);
  out[pos++] = ',';
  for (uint8_t i = 0; i < 3u && kind[i]; ++i) out[pos++] = kind[i];
  for (uint8_t i = 0; i < count; ++i) {
    out[pos++] = ',';
    pos = sds_put_signed(out, pos, values[i]);
  }
  uint8_t checksum = 0;
  for (size_t i = 1; i < pos; ++i) checksum ^= (uint8_t)out[i];
  const char *hex = "0123456789ABCDEF";
  out[pos++] = '*';
  out[pos++] = hex[checksum >> 4];
  out[pos++] = hex[checksum & 0x0F];
  out[pos++] = '\r';
  out[pos++] = '\n';
  if (pos > SDS_MAX_LINE) return 0u;
  out[pos] = '\0';
  return pos;
}

#endif  // SDS_PROTOCOL_H
