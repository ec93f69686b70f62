#include "topo_planner/plan_manage/yaml_params.h"

namespace topo_planner {

std::optional<YamlParams> YamlParams::load(const std::string& path, std::string* why) {
  try {
    YAML::Node root = YAML::LoadFile(path);
    if (!root.IsMap()) {
      if (why) *why = path + ": not a map of parameters";
      return std::nullopt;
    }
    return YamlParams(root);
  } catch (const YAML::Exception& e) {
    if (why) *why = path + ": " + e.what();
    return std::nullopt;
  }
}

std::optional<YamlParams> YamlParams::parse(const std::string& text, std::string* why) {
  try {
    YAML::Node root = YAML::Load(text);
    if (!root.IsMap()) {
      if (why) *why = "not a map of parameters";
      return std::nullopt;
    }
    return YamlParams(root);
  } catch (const YAML::Exception& e) {
    if (why) *why = e.what();
    return std::nullopt;
  }
}

YAML::Node YamlParams::find(const std::string& name) const {
  // Clone-free descent: operator[] on a const node never inserts.
  std::vector<YAML::Node> path{root_};
  size_t begin = 0;
  while (begin <= name.size()) {
    const size_t end = std::min(name.find('/', begin), name.size());
    const std::string key = name.substr(begin, end - begin);
    const YAML::Node& at = path.back();
    if (key.empty() || !at.IsMap()) return YAML::Node(YAML::NodeType::Undefined);
    const YAML::Node next = static_cast<const YAML::Node&>(at)[key];
    if (!next) return YAML::Node(YAML::NodeType::Undefined);
    path.push_back(next);
    begin = end + 1;
  }
  return path.back();
}

bool YamlParams::set(const std::string& name, const std::string& yaml_value) {
  YAML::Node value;
  try {
    value = YAML::Load(yaml_value);
  } catch (const YAML::Exception&) {
    return false;
  }
  YAML::Node at = root_;
  size_t begin = 0;
  while (true) {
    const size_t end = name.find('/', begin);
    const std::string key = name.substr(begin, end == std::string::npos ? std::string::npos : end - begin);
    if (key.empty() || !at.IsMap()) return false;
    if (end == std::string::npos) {
      at[key] = value;
      return true;
    }
    YAML::Node next = at[key];
    if (!next.IsDefined() || next.IsNull()) next = YAML::Node(YAML::NodeType::Map);
    at[key] = next;
    at.reset(next);  // descend without assigning through the reference
    begin = end + 1;
  }
}

}  // namespace topo_planner
