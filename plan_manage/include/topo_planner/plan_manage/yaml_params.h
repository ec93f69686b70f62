#pragma once
// Parameters from a YAML file without ROS: the reader planner_params.h expects (read(name, value),
// errors()), over a file such as config/planner.yaml. Names are paths of nested maps joined by '/'
// ("fsm/brake_acc_mps2"); a name that is absent leaves the value as it is, one of the wrong type is
// reported in errors(). The ROS-free closed loop (sim_flight.h) reads the node's configuration with it.

#include <yaml-cpp/yaml.h>

#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace topo_planner {

class YamlParams {
 public:
  /// The file's top-level map; nullopt with the reason when it cannot be read or parsed.
  static std::optional<YamlParams> load(const std::string& path, std::string* why);
  /// From YAML text (tests).
  static std::optional<YamlParams> parse(const std::string& text, std::string* why);

  void read(const std::string& name, double& value) { readAs(name, value); }
  void read(const std::string& name, int& value) { readAs(name, value); }
  void read(const std::string& name, bool& value) { readAs(name, value); }
  void read(const std::string& name, std::string& value) { readAs(name, value); }
  void read(const std::string& name, std::vector<double>& value) { readAs(name, value); }
  bool has(const std::string& name) const { return bool(find(name)); }
  /// Sets (or adds) a parameter from YAML text, e.g. set("fsm/brake_acc_mps2", "3.0"): an override
  /// from a command line. False when the text does not parse or a parent is not a map.
  bool set(const std::string& name, const std::string& yaml_value);
  std::ostringstream& errors() { return errors_; }

 private:
  explicit YamlParams(YAML::Node root) : root_(std::move(root)) {}
  /// The node at a '/'-separated path; an undefined node when absent.
  YAML::Node find(const std::string& name) const;
  template <typename T>
  void readAs(const std::string& name, T& value) {
    const YAML::Node n = find(name);
    if (!n) return;
    try {
      value = n.as<T>();
    } catch (const YAML::Exception&) {
      errors_ << name << " has the wrong type; ";
    }
  }

  YAML::Node root_;
  std::ostringstream errors_;
};

}  // namespace topo_planner
