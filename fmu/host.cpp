#include "fmu/host.hpp"

#include <cstring>
#include <fstream>
#include <sstream>

#include <fmt/format.h>

namespace twin::fmu {
namespace {

struct CategoryName {
  const char* name;
  unsigned bit;
};
constexpr CategoryName kCategories[] = {{"logCalls", kLogCalls},
                                        {"logStatusWarning", kLogStatusWarning},
                                        {"logStatusDiscard", kLogStatusDiscard},
                                        {"logStatusError", kLogStatusError},
                                        {"logStatusFatal", kLogStatusFatal}};

const char* category_name(unsigned bit) {
  for (const auto& c : kCategories)
    if (c.bit == bit) return c.name;
  return "logStatusError";
}

}  // namespace

const char* call_state_name(CallState s) {
  switch (s) {
    case CallState::kInstantiated: return "instantiated";
    case CallState::kInitialization: return "initialization mode";
    case CallState::kStepMode: return "step mode";
    case CallState::kTerminated: return "terminated";
    case CallState::kError: return "error";
  }
  return "?";
}

unsigned category_bits(std::size_t n, const char* const names[]) {
  if (n == 0) return kAllCategories;
  if (names == nullptr) throw ConfigError(fmt::format("nCategories = {} with a null array", n));
  unsigned bits = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const char* name = names[i];
    unsigned bit = 0;
    for (const auto& cat : kCategories)
      if (name != nullptr && std::strcmp(name, cat.name) == 0) bit = cat.bit;
    if (bit == 0)
      throw ConfigError(fmt::format(
          "category '{}' is not one of the FMU's (logCalls, logStatusWarning, logStatusDiscard, logStatusError, "
          "logStatusFatal)",
          name != nullptr ? name : "(null)"));
    bits |= bit;
  }
  return bits;
}

std::string with_function(const char* function, const std::string& what) {
  const std::string prefix = std::string(function) + ": ";
  return what.rfind(prefix, 0) == 0 ? what : prefix + what;
}

void Instance::require(std::initializer_list<CallState> allowed) const {
  for (CallState s : allowed)
    if (s == state_) return;
  throw ConfigError(fmt::format("not allowed in state '{}'", call_state_name(state_)));
}

void Instance::fail() noexcept {
  state_ = CallState::kError;
  slave_->mark_failed();
}

void Instance::emit(Status status, unsigned category, const std::string& message) const {
  const bool always = category == kLogStatusError || category == kLogStatusFatal;
  if (!always && (categories_ & category) == 0) return;
  if (sink_) sink_(status, category_name(category), message);
}

void Instance::log_error(Status status, const char* function, const std::string& what) const {
  emit(status, status == Status::kFatal ? kLogStatusFatal : kLogStatusError, with_function(function, what));
}

void Instance::log_call(const char* function, const std::string& what) const {
  if (!logs_calls()) return;
  emit(Status::kOk, kLogCalls, with_function(function, what));
}

void Instance::set_experiment(double start_s, std::optional<double> stop_s) {
  require({CallState::kInstantiated});
  slave_->set_experiment(start_s, stop_s);
}

void Instance::enter_initialization() {
  require({CallState::kInstantiated});
  state_ = CallState::kInitialization;
}

void Instance::exit_initialization() {
  require({CallState::kInitialization});
  slave_->start();
  state_ = CallState::kStepMode;
}

std::int64_t Instance::do_step(double t_s, double h_s) {
  require({CallState::kStepMode});
  return slave_->step(t_s, h_s);
}

void Instance::terminate() {
  require({CallState::kStepMode});
  state_ = CallState::kTerminated;
}

void Instance::reset() {
  slave_->reset();
  state_ = CallState::kInstantiated;
}

void Instance::require_get() const {
  require({CallState::kInitialization, CallState::kStepMode, CallState::kTerminated, CallState::kError});
}

void Instance::require_set() const {
  require({CallState::kInstantiated, CallState::kInitialization, CallState::kStepMode});
}

std::unique_ptr<SavedState> Instance::save() const {
  require({CallState::kInstantiated, CallState::kInitialization, CallState::kStepMode, CallState::kTerminated});
  return std::make_unique<SavedState>(slave_->save(static_cast<std::int32_t>(state_)));
}

void Instance::check_state(const SavedState& s) const {
  auto refuse = [](const std::string& why) { throw ConfigError(fmt::format("the FMU state is refused: {}", why)); };
  if (s.magic != kStateMagic) refuse("it was not made by this FMU");
  if (s.host_state < 0 || s.host_state >= static_cast<std::int32_t>(CallState::kError))
    refuse(fmt::format("call state {} cannot be restored", s.host_state));
  slave_->check_state(s);
  const auto state = static_cast<CallState>(s.host_state);
  const bool running = state == CallState::kStepMode || state == CallState::kTerminated;
  if (s.has_cosim != running)
    refuse(fmt::format("call state '{}' {} a running co-simulation", call_state_name(state),
                       s.has_cosim ? "with" : "without"));
}

void Instance::restore(const SavedState& s) {
  check_state(s);
  slave_->restore(s);
  state_ = static_cast<CallState>(s.host_state);
}

const SavedState& saved_state(const void* handle) {
  if (handle == nullptr) throw ConfigError("FMUstate is null");
  const auto* s = static_cast<const SavedState*>(handle);
  if (s->magic != kStateMagic) throw ConfigError("FMUstate was not made by this FMU");
  return *s;
}

namespace {

/// Puts `saved` behind `handle`, freeing the state it held (if ours).
void replace_state(void** handle, std::unique_ptr<SavedState> saved) {
  if (*handle != nullptr) {
    saved_state(*handle);  // refuse to overwrite what is not ours
    delete static_cast<SavedState*>(*handle);
  }
  *handle = saved.release();
}

}  // namespace

void get_state(const Instance& inst, void** handle) {
  if (handle == nullptr) throw ConfigError("FMUstate pointer is null");
  replace_state(handle, inst.save());
}

void set_state(Instance& inst, const void* handle) { inst.restore(saved_state(handle)); }

void free_state(void** handle) {
  if (handle == nullptr || *handle == nullptr) return;
  saved_state(*handle);
  delete static_cast<SavedState*>(*handle);
  *handle = nullptr;
}

std::size_t serialized_state_size(const void* handle) { return serialize_state(saved_state(handle)).size(); }

void serialize_state(const void* handle, char* bytes, std::size_t size) {
  if (bytes == nullptr) throw ConfigError("byte array is null");
  const std::vector<char> b = serialize_state(saved_state(handle));
  if (b.size() != size) throw ConfigError(fmt::format("buffer of {} bytes, the state has {}", size, b.size()));
  std::memcpy(bytes, b.data(), b.size());
}

void deserialize_state(const Instance& inst, const char* bytes, std::size_t size, void** handle) {
  if (bytes == nullptr || handle == nullptr) throw ConfigError("null argument");
  auto s = std::make_unique<SavedState>(deserialize_state(bytes, size));
  inst.check_state(*s);
  replace_state(handle, std::move(s));
}

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError("cannot read " + path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

std::unique_ptr<Slave> make_slave(const std::string& resources, const char* given, const char* what,
                                  std::string (*expected)(const FmuModel&)) {
  const std::string model_path = resources + "/model.json";
  FmuModel model = model_from_json(read_text(model_path), model_path);
  std::string identity = expected(model);
  if (identity != given)
    throw ConfigError(fmt::format("{} {} does not match this FMU's {} (modelDescription.xml and binary or "
                                  "resources/model.json differ)",
                                  what, given, identity));
  return std::make_unique<Slave>(std::move(model), std::move(identity));
}

}  // namespace twin::fmu
