// Hot-plug arrivals and removals of the known RGB-D cameras (hal/usb/usb_ids.h),
// reported to the service: counters and a bounded queue of events it drains
// and logs ("usb: Orbbec Astra arrived at 1-2").
//
// A thread of its own ("fovea-usb") runs libusb's event loop with a 100 ms
// timeout, so stop() returns within about that. libusb calls the hot-plug
// callback on that thread (and, for devices already present when
// report_present is set, inside start()); the callback copies the ids and the
// port path into a preallocated slot: no allocation beyond libusb's own. When
// the queue is full the event is dropped and counted; the counters stay exact.
//
// Without hot-plug support (libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG) is
// false, or fovea was built without libusb) start() returns kUnavailable with
// the reason, counters().available stays false, and nothing else happens.
#pragma once

#include <array>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "core/result.h"
#include "hal/usb/usb_ids.h"

namespace fovea::hal::usb {

struct UsbEvent {
  enum class Kind : uint8_t { kArrived, kLeft };
  Kind kind = Kind::kArrived;
  const KnownUsbCamera* known = nullptr;  // the table entry (never null)
  uint16_t vendor_id = 0;
  uint16_t product_id = 0;
  uint8_t bus = 0;
  uint8_t address = 0;
  std::array<char, 24> port_path{};  // "1-2.3", NUL-terminated (USB allows 7 tiers)
  bool present_at_start = false;      // reported by start() for a device already there
};

// "usb: Orbbec Astra (2bc5:0401) arrived at 1-2" / "... left 1-2"; no allocation.
std::size_t formatUsbEvent(const UsbEvent& event, char* out, std::size_t size);

struct UsbMonitorCounters {
  bool available = false;  // hot-plug is running
  uint64_t arrivals = 0;   // known cameras that arrived (present_at_start ones included)
  uint64_t removals = 0;
  uint64_t dropped_events = 0;  // not queued: the queue was full
};

struct UsbMonitorOptions {
  std::size_t queue_capacity = 32;
  // Also report the known cameras already connected at start() as arrivals.
  bool report_present = false;
  // Also report devices that are not in the table (tests); their `known` is null.
  bool any_device = false;
};

class UsbMonitor {
 public:
  explicit UsbMonitor(const UsbMonitorOptions& options = {});
  ~UsbMonitor();  // stop()
  UsbMonitor(const UsbMonitor&) = delete;
  UsbMonitor& operator=(const UsbMonitor&) = delete;

  // Initialises libusb, registers the callback and starts the thread.
  // kUnavailable when the platform (or build) has no hot-plug; kIoError when
  // libusb cannot start. Calling it while running does nothing.
  Status start();
  // Deregisters, stops and joins the thread, closes libusb (idempotent).
  void stop();
  bool running() const;

  // Takes the oldest queued event; false when none. One consumer at a time.
  bool poll(UsbEvent& event);
  // Waits up to `timeout` for an event (tests); false on timeout.
  bool waitEvent(UsbEvent& event, std::chrono::milliseconds timeout);

  UsbMonitorCounters counters() const;
  // Why start() failed ("" when it did not).
  const std::string& unavailableReason() const { return unavailable_reason_; }
  // Set by a successful start() when events are unlikely to arrive: Debian's
  // libusb hears hot-plug through udevd, and udevd is not running (a container,
  // an initramfs). "" otherwise.
  const std::string& warning() const { return warning_; }

  struct Impl;  // public for the libusb callback, defined in the .cpp

 private:
  std::unique_ptr<Impl> impl_;
  std::string unavailable_reason_;
  std::string warning_;
};

}  // namespace fovea::hal::usb
