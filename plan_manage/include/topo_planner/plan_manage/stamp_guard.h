#pragma once
// A message_filters stage that drops messages whose header stamp the synchronisers cannot handle.
//
// message_filters' ApproximateTime subtracts stamps into ros::Duration, which throws (and so aborts
// the node from inside a callback) when the difference exceeds 2^31 s. Any two stamps below 2^31 s
// (2038-01-19) are safe, so larger ones are refused here, before the synchroniser sees them.

#include <message_filters/connection.h>
#include <message_filters/simple_filter.h>
#include <ros/console.h>
#include <ros/message_event.h>

#include <cstdint>
#include <limits>

namespace topo_planner {

/// True when `stamp` can be safely subtracted from any other stamp that passes this test.
inline bool stampInDurationRange(const ros::Time& stamp) {
  return stamp.sec <= uint32_t(std::numeric_limits<int32_t>::max());
}

template <class M>
class StampGuard : public message_filters::SimpleFilter<M> {
 public:
  using EventType = ros::MessageEvent<M const>;

  template <class F>
  void connectInput(F& f) {
    incoming_.disconnect();
    incoming_ = f.registerCallback(
        typename message_filters::SimpleFilter<M>::EventCallback([this](const EventType& e) { add(e); }));
  }

  void add(const EventType& e) {
    const ros::Time& stamp = e.getConstMessage()->header.stamp;
    if (!stampInDurationRange(stamp)) {
      ROS_WARN_THROTTLE(1.0, "mapping: message stamped %u s dropped (stamps past 2^31 s break the synchroniser)",
                        stamp.sec);
      return;
    }
    this->signalMessage(e);
  }

 private:
  message_filters::Connection incoming_;
};

}  // namespace topo_planner
