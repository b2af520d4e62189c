#include "hal/usb/usb_monitor.h"

#include <libusb.h>
#include <unistd.h>

#include <atomic>
#include <condition_variable>
#include <cstring>
#include <mutex>
#include <thread>
#include <vector>

#include "hal/usb/libusb_support.h"

namespace fovea::hal::usb {

struct UsbMonitor::Impl {
  explicit Impl(const UsbMonitorOptions& o) : options(o), queue(o.queue_capacity == 0 ? 1 : o.queue_capacity) {}

  // From the callback: copy into a free slot, or count the drop. No allocation.
  void push(const UsbEvent& event) {
    {
      std::lock_guard<std::mutex> lock(mu);
      if (queued == queue.size()) {
        dropped.fetch_add(1, std::memory_order_relaxed);
        return;
      }
      queue[(head + queued) % queue.size()] = event;
      ++queued;
    }
    cv.notify_one();
  }

  bool pop(UsbEvent& event) {
    std::lock_guard<std::mutex> lock(mu);
    if (queued == 0) return false;
    event = queue[head];
    head = (head + 1) % queue.size();
    --queued;
    return true;
  }

  UsbMonitorOptions options;
  detail::LibusbContext ctx;
  libusb_hotplug_callback_handle handle = 0;
  bool registered = false;
  bool starting = false;  // inside libusb_hotplug_register_callback (present devices)
  std::thread thread;
  std::atomic<bool> run{false};
  std::atomic<bool> available{false};
  std::atomic<uint64_t> arrivals{0}, removals{0}, dropped{0};
  std::mutex mu;
  std::condition_variable cv;
  std::vector<UsbEvent> queue;  // a ring: `queued` events from `head`
  std::size_t head = 0;
  std::size_t queued = 0;
};

namespace {

int LIBUSB_CALL hotplugCallback(libusb_context*, libusb_device* device, libusb_hotplug_event what, void* user) {
  auto* impl = static_cast<UsbMonitor::Impl*>(user);
  libusb_device_descriptor desc{};
  if (libusb_get_device_descriptor(device, &desc) != 0) return 0;
  const KnownUsbCamera* known = findKnownUsbCamera(desc.idVendor, desc.idProduct);
  if (known == nullptr && !impl->options.any_device) return 0;
  UsbEvent event;
  event.kind = what == LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED ? UsbEvent::Kind::kArrived : UsbEvent::Kind::kLeft;
  event.known = known;
  event.vendor_id = desc.idVendor;
  event.product_id = desc.idProduct;
  event.bus = libusb_get_bus_number(device);
  event.address = libusb_get_device_address(device);
  event.present_at_start = impl->starting;
  detail::formatPortPath(device, event.port_path.data(), event.port_path.size());
  if (known != nullptr) {
    (event.kind == UsbEvent::Kind::kArrived ? impl->arrivals : impl->removals).fetch_add(1, std::memory_order_relaxed);
  }
  impl->push(event);
  return 0;  // stay registered
}

}  // namespace

UsbMonitor::UsbMonitor(const UsbMonitorOptions& options) : impl_(std::make_unique<Impl>(options)) {}

UsbMonitor::~UsbMonitor() { stop(); }

Status UsbMonitor::start() {
  if (running()) return Status::ok();
  unavailable_reason_.clear();
  if (Status s = usbHotplugSupported(); !s) {
    unavailable_reason_ = s.message();
    return s;
  }
  if (Status s = impl_->ctx.init(); !s) {
    unavailable_reason_ = s.message();
    return s;
  }
  const int flags = impl_->options.report_present ? LIBUSB_HOTPLUG_ENUMERATE : 0;
  impl_->starting = true;
  const int r = libusb_hotplug_register_callback(
      impl_->ctx.get(),
      static_cast<libusb_hotplug_event>(LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED | LIBUSB_HOTPLUG_EVENT_DEVICE_LEFT),
      static_cast<libusb_hotplug_flag>(flags), LIBUSB_HOTPLUG_MATCH_ANY, LIBUSB_HOTPLUG_MATCH_ANY,
      LIBUSB_HOTPLUG_MATCH_ANY, &hotplugCallback, impl_.get(), &impl_->handle);
  impl_->starting = false;
  if (r != LIBUSB_SUCCESS) {
    unavailable_reason_ = "libusb hot-plug registration failed: " + detail::libusbErrorText(r);
    impl_->ctx.reset();
    return {r == LIBUSB_ERROR_NOT_SUPPORTED ? ErrorCode::kUnavailable : ErrorCode::kIoError, unavailable_reason_};
  }
  impl_->registered = true;
  impl_->run.store(true, std::memory_order_release);
  Impl* impl = impl_.get();
  impl_->thread = std::thread([impl] {
    pthread_setname_np(pthread_self(), "fovea-usb");
    while (impl->run.load(std::memory_order_acquire)) {
      timeval tv{0, 100'000};  // bounds how long stop() waits
      libusb_handle_events_timeout_completed(impl->ctx.get(), &tv, nullptr);
    }
  });
  impl_->available.store(true, std::memory_order_relaxed);
  warning_.clear();
  if (access("/run/udev/control", F_OK) != 0) {
    warning_ = "udevd is not running (no /run/udev/control): libusb hears hot-plug events through udev, so "
               "arrivals and removals will not be reported";
  }
  return Status::ok();
}

void UsbMonitor::stop() {
  if (!impl_->registered) return;
  impl_->run.store(false, std::memory_order_release);
  // Deregistering wakes the event loop, so the thread sees run == false at once.
  libusb_hotplug_deregister_callback(impl_->ctx.get(), impl_->handle);
  if (impl_->thread.joinable()) impl_->thread.join();
  impl_->registered = false;
  impl_->available.store(false, std::memory_order_relaxed);
  impl_->ctx.reset();
}

bool UsbMonitor::running() const { return impl_->registered; }

bool UsbMonitor::poll(UsbEvent& event) { return impl_->pop(event); }

bool UsbMonitor::waitEvent(UsbEvent& event, std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(impl_->mu);
  if (!impl_->cv.wait_for(lock, timeout, [&] { return impl_->queued > 0; })) return false;
  event = impl_->queue[impl_->head];
  impl_->head = (impl_->head + 1) % impl_->queue.size();
  --impl_->queued;
  return true;
}

UsbMonitorCounters UsbMonitor::counters() const {
  UsbMonitorCounters c;
  c.available = impl_->available.load(std::memory_order_relaxed);
  c.arrivals = impl_->arrivals.load(std::memory_order_relaxed);
  c.removals = impl_->removals.load(std::memory_order_relaxed);
  c.dropped_events = impl_->dropped.load(std::memory_order_relaxed);
  return c;
}

}  // namespace fovea::hal::usb
