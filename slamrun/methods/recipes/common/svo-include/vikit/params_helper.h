// slamrun: a ROS-free stand-in for rpg_vikit's vikit_ros/include/vikit/params_helper.h, so the svo library of
// SVO and of CNN-SVO (config.cpp; CNN-SVO's frame handlers too) builds and reads its parameters without ROS.
// vk::getParam(name[, default]) looks `name` up in a flat "key: value" file (rosparam YAML as slamrun writes it:
// `svo/max_fts: 120`, `svo/cam_model: "Pinhole"`); a key `svo/x` also matches a bare `x` (the authors' param/*.yaml).
// The file is named by the environment variable SVO_PARAMS (the driver sets it from its argument).
#ifndef SLAMRUN_VIKIT_PARAMS_HELPER_H_
#define SLAMRUN_VIKIT_PARAMS_HELPER_H_

#include <cstdlib>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <string>

namespace vk {
namespace slamrun_params {

inline std::string trim(const std::string& s) {
  const char* ws = " \t\r\n";
  size_t a = s.find_first_not_of(ws);
  if (a == std::string::npos) return "";
  return s.substr(a, s.find_last_not_of(ws) - a + 1);
}

inline const std::map<std::string, std::string>& table() {
  static std::map<std::string, std::string> values = [] {
    std::map<std::string, std::string> v;
    const char* path = std::getenv("SVO_PARAMS");
    if (!path || !*path) return v;
    std::ifstream in(path);
    if (!in) {
      std::cerr << "[params] cannot read SVO_PARAMS=" << path << std::endl;
      std::exit(2);
    }
    std::string line;
    while (std::getline(in, line)) {
      bool quoted = false;
      for (size_t i = 0; i < line.size(); ++i) {  // drop comments outside quotes
        if (line[i] == '"') quoted = !quoted;
        else if (line[i] == '#' && !quoted) { line.resize(i); break; }
      }
      size_t colon = line.find(':');
      if (colon == std::string::npos) continue;
      std::string key = trim(line.substr(0, colon)), value = trim(line.substr(colon + 1));
      if (value.size() >= 2 && (value[0] == '"' || value[0] == '\'') && value.back() == value[0])
        value = value.substr(1, value.size() - 2);
      if (!key.empty()) v[key] = value;
    }
    return v;
  }();
  return values;
}

inline bool lookup(const std::string& name, std::string& value) {
  const auto& t = table();
  auto it = t.find(name);
  if (it == t.end() && name.compare(0, 4, "svo/") == 0) it = t.find(name.substr(4));
  if (it == t.end()) return false;
  value = it->second;
  return true;
}

template <typename T>
inline bool convert(const std::string& text, T& out) {
  std::istringstream in(text);
  in >> out;
  return !in.fail();
}
template <>
inline bool convert<std::string>(const std::string& text, std::string& out) { out = text; return true; }
template <>
inline bool convert<bool>(const std::string& text, bool& out) {
  if (text == "true" || text == "True" || text == "1") { out = true; return true; }
  if (text == "false" || text == "False" || text == "0") { out = false; return true; }
  return false;
}

}  // namespace slamrun_params

inline bool hasParam(const std::string& name) {
  std::string v;
  return slamrun_params::lookup(name, v);
}

template <typename T>
T getParam(const std::string& name, const T& defaultValue) {
  std::string text;
  T v;
  if (slamrun_params::lookup(name, text)) {
    if (slamrun_params::convert(text, v)) {
      std::cerr << "[params] " << name << " = " << v << std::endl;
      return v;
    }
    std::cerr << "[params] " << name << ": cannot parse '" << text << "'" << std::endl;
    std::exit(2);
  }
  return defaultValue;
}

template <typename T>
T getParam(const std::string& name) {
  std::string text;
  T v;
  if (slamrun_params::lookup(name, text) && slamrun_params::convert(text, v)) return v;
  std::cerr << "[params] required parameter " << name << " is missing or invalid" << std::endl;
  std::exit(2);
}

}  // namespace vk

#endif  // SLAMRUN_VIKIT_PARAMS_HELPER_H_
