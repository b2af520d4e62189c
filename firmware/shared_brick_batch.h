// The map's bricks of a frame on their way from the foveation stage (which
// plans and samples them) to the send stage (which encodes them): one batch for
// the service, lent to the frame of the foveated ring that carries it.
//
// Why one: each slot of the ring held a batch of its own before, sized for what
// the link's largest budget pays for in a frame (1.5 MiB at the defaults, three
// slots), yet the send stage is done with a batch once it has encoded it
// (Streamer::setBricksDoneHook), a millisecond or two after it takes the frame
// and long before the next frame's plan. A frame planned while the batch is
// still out carries no bricks (counted: deferred); its bricks stay due and the
// next frame's plan takes them, with the budget of both frames' time.
//
// Who owns it: owner() is the ring slot of the frame that carries it, or kFree.
// The foveation stage lends it (before it publishes the slot) and takes it back
// from a slot the ring dropped before the send stage took it (a slot that comes
// back to the producer still the owner); the send stage gives it back when its
// encode is done. The ring's publish and take order the batch's contents; the
// owner's release and acquire order the give-back against the next plan.
#pragma once

#include <atomic>
#include <cstdint>
#include <utility>

#include "core/ring.h"
#include "pipeline/map/brick_batch.h"

namespace fovea::firmware {

class SharedBrickBatch {
 public:
  static constexpr SlotIndex kFree = UINT32_MAX;

  explicit SharedBrickBatch(pipeline::map::BrickBatch batch) : batch_(std::move(batch)) {}
  SharedBrickBatch(const SharedBrickBatch&) = delete;
  SharedBrickBatch& operator=(const SharedBrickBatch&) = delete;

  pipeline::map::BrickBatch& batch() { return batch_; }
  const pipeline::map::BrickBatch& batch() const { return batch_; }
  SlotIndex owner() const { return owner_.load(std::memory_order_acquire); }
  bool ownedBy(SlotIndex slot) const { return owner() == slot; }

  // ---- the foveation stage ----
  bool available() const { return owner() == kFree; }
  void lend(SlotIndex slot) { owner_.store(slot, std::memory_order_release); }
  // A slot the ring dropped still owns the batch: nobody else can give it back.
  void takeBack() { owner_.store(kFree, std::memory_order_release); }

  // ---- the send stage ----
  // Done with the frame of `slot`'s bricks; false when that frame does not carry it.
  bool giveBack(SlotIndex slot) {
    SlotIndex expected = slot;
    return owner_.compare_exchange_strong(expected, kFree, std::memory_order_acq_rel, std::memory_order_acquire);
  }

 private:
  pipeline::map::BrickBatch batch_;
  std::atomic<SlotIndex> owner_{kFree};
};

}  // namespace fovea::firmware
