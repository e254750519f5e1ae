// SDS Arduino (Mega 2560): the seed's redundant sensors and switches, autonomous during a drop.
//
// - MPU6050 accelerometer (I2C 0x68, ±16 g) at 200 Hz -> IMU records [mg]
// - VL53L0X time of flight (I2C 0x29, back-to-back, 33 ms budget) -> TOF records [mm, status]
// - capsule trigger input (pin 2, interrupt, active high) -> TRG records; on the trigger the
//   lasers switch on (LAS) and the sync LED blinks once (LED on/off, 200 ms)
// - MOSFET gates: laser diodes + line laser (pin 7), sync LED (pin 8)
// - every record goes to the serial line (115200 baud) and to SDS_LOG.TXT on the SD card
//   (chip select pin 53), flushed once a second
// Protocol: protocol.h (version 1); reference and parser: src/sds_arduino/sds_arduino/protocol.py.
// Libraries: Wire, SPI, SD (Arduino) and VL53L0X (Pololu) — see firmware/README.md.

#include <SD.h>
#include <SPI.h>
#include <VL53L0X.h>
#include <Wire.h>

#include "protocol.h"

const uint8_t PIN_TRIGGER = 2;
const uint8_t PIN_LASERS = 7;
const uint8_t PIN_LED = 8;
const uint8_t PIN_SD_CS = 53;
const uint8_t MPU6050 = 0x68;
const uint32_t IMU_PERIOD_US = 5000;     // 200 Hz
const uint32_t TOF_POLL_US = 2000;       // readiness checks; a range every ~33 ms
const uint32_t LED_BLINK_US = 200000;
const uint32_t SD_FLUSH_US = 1000000;

VL53L0X tof;
File sdLog;
bool sdReady = false;
uint32_t sequence = 0;
uint32_t lastImu = 0, lastTof = 0, lastFlush = 0, ledOnAt = 0;
bool ledOn = false;
volatile bool triggerChanged = false;
bool triggerLevel = false;

void emit(const char *kind, const int32_t *values, uint8_t count) {
  char line[SDS_MAX_LINE + 1];
  size_t length = sds_format(line, sequence++, micros(), kind, values, count);
  if (length == 0) return;
  Serial.write(line, length);
  if (sdReady) sdLog.write(line, length);
}

void emitState(const char *kind, bool state) {
  int32_t value = state ? 1 : 0;
  emit(kind, &value, 1);
}

void onTrigger() { triggerChanged = true; }

void writeRegister(uint8_t device, uint8_t reg, uint8_t value) {
  Wire.beginTransmission(device);
  Wire.write(reg);
  Wire.write(value);
  Wire.endTransmission();
}

void setupImu() {
  writeRegister(MPU6050, 0x6B, 0x00);  // PWR_MGMT_1: wake up, internal clock
  writeRegister(MPU6050, 0x1C, 0x18);  // ACCEL_CONFIG: ±16 g (2048 LSB/g)
  writeRegister(MPU6050, 0x1A, 0x03);  // CONFIG: 44 Hz low-pass against aliasing at 200 Hz
}

void readImu() {
  Wire.beginTransmission(MPU6050);
  Wire.write(0x3B);  // ACCEL_XOUT_H
  Wire.endTransmission(false);
  if (Wire.requestFrom(MPU6050, (uint8_t)6) != 6) return;
  int32_t mg[3];
  for (uint8_t axis = 0; axis < 3; ++axis) {
    int16_t raw = (int16_t)((Wire.read() << 8) | Wire.read());
    mg[axis] = ((int32_t)raw * 1000) / 2048;
  }
  emit("IMU", mg, 3);
}

void pollTof() {
  // Read only a finished measurement: a blocking read would stall the 200 Hz IMU.
  if ((tof.readReg(VL53L0X::RESULT_INTERRUPT_STATUS) & 0x07) == 0) return;
  int32_t values[2];
  values[0] = tof.readRangeContinuousMillimeters();
  values[1] = tof.timeoutOccurred() ? 1 : 0;
  emit("TOF", values, 2);
}

void setup() {
  pinMode(PIN_LASERS, OUTPUT);
  pinMode(PIN_LED, OUTPUT);
  pinMode(PIN_TRIGGER, INPUT);
  digitalWrite(PIN_LASERS, LOW);
  digitalWrite(PIN_LED, LOW);
  Serial.begin(115200);
  Wire.begin();
  Wire.setClock(400000);
  setupImu();
  tof.setTimeout(50);
  if (tof.init()) tof.startContinuous(0);
  sdReady = SD.begin(PIN_SD_CS);
  if (sdReady) sdLog = SD.open("SDS_LOG.TXT", FILE_WRITE);
  sdReady = sdReady && sdLog;
  attachInterrupt(digitalPinToInterrupt(PIN_TRIGGER), onTrigger, CHANGE);
  emitState("LAS", false);
}

void loop() {
  uint32_t now = micros();
  if (now - lastImu >= IMU_PERIOD_US) {
    lastImu += IMU_PERIOD_US;
    readImu();
  }
  if (now - lastTof >= TOF_POLL_US) {
    lastTof = now;
    pollTof();
  }
  if (triggerChanged) {
    triggerChanged = false;
    bool level = digitalRead(PIN_TRIGGER) == HIGH;
    if (level != triggerLevel) {
      triggerLevel = level;
      emitState("TRG", level);
      if (level) {  // the drop starts: lasers on, one sync blink for the cameras
        digitalWrite(PIN_LASERS, HIGH);
        emitState("LAS", true);
        digitalWrite(PIN_LED, HIGH);
        ledOn = true;
        ledOnAt = now;
        emitState("LED", true);
      }
    }
  }
  if (ledOn && now - ledOnAt >= LED_BLINK_US) {
    digitalWrite(PIN_LED, LOW);
    ledOn = false;
    emitState("LED", false);
  }
  if (sdReady && now - lastFlush >= SD_FLUSH_US) {
    lastFlush = now;
    sdLog.flush();
  }
}
