#include "fmu_importer.hpp"

#include <dlfcn.h>
#include <zip.h>

#include <sys/wait.h>

#include <array>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <stdexcept>

namespace twin::fmu_test {
namespace {

void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
            fmi2String message, ...) {
  char buf[4096];
  va_list args;
  va_start(args, message);
  std::vsnprintf(buf, sizeof buf, message, args);
  va_end(args);
  auto* log = static_cast<std::vector<std::string>*>(env);
  log->push_back(std::string(instance ? instance : "?") + " [" + std::to_string(static_cast<int>(status)) + "] " +
                 (category ? category : "") + ": " + buf);
}

}  // namespace

std::string xml_attribute(const std::string& element, const std::string& name) {
  const std::regex re("\\s" + name + "=\"([^\"]*)\"");
  std::smatch m;
  if (std::regex_search(element, m, re)) return m[1];
  return {};
}

std::string default_experiment_attribute(const std::string& xml, const std::string& name) {
  const std::regex de("<DefaultExperiment[^>]*>");
  std::smatch m;
  if (!std::regex_search(xml, m, de)) return {};
  return xml_attribute(m[0], name);
}

std::string read_text_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string export_error(const std::string& fmu) { return read_text_file(fmu + ".error"); }

int run(const std::string& cmd, std::string& out) {
  out.clear();
  std::FILE* p = ::popen((cmd + " 2>&1").c_str(), "r");
  if (p == nullptr) return -1;
  std::array<char, 4096> buf{};
  while (std::fgets(buf.data(), buf.size(), p) != nullptr) out += buf.data();
  const int rc = ::pclose(p);
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

int validate_with_xsd(const std::string& xsd, const std::string& xml_file, std::string& out) {
  return run("xmllint --noout --nonet --schema " + xsd + " " + xml_file, out);
}

std::string python3() {
#ifdef TWIN_SANITIZER_RUNTIME
  return "LD_PRELOAD=" TWIN_SANITIZER_RUNTIME " ASAN_OPTIONS=detect_leaks=0 python3 ";
#else
  return "python3 ";
#endif
}

std::string extract_fmu(const std::string& fmu) {
  int err = 0;
  zip_t* z = zip_open(fmu.c_str(), ZIP_RDONLY, &err);
  if (z == nullptr) throw std::runtime_error("cannot open " + fmu + " (libzip error " + std::to_string(err) + ")");
  std::string tmpl = (std::filesystem::temp_directory_path() / "twin_fmu_XXXXXX").string();
  if (::mkdtemp(tmpl.data()) == nullptr) throw std::runtime_error("mkdtemp failed");
  const zip_int64_t n = zip_get_num_entries(z, 0);
  for (zip_int64_t i = 0; i < n; ++i) {
    const std::string name = zip_get_name(z, static_cast<zip_uint64_t>(i), 0);
    const std::filesystem::path out = std::filesystem::path(tmpl) / name;
    std::filesystem::create_directories(out.parent_path());
    zip_file_t* f = zip_fopen_index(z, static_cast<zip_uint64_t>(i), 0);
    if (f == nullptr) throw std::runtime_error("cannot read " + name + " in " + fmu);
    std::ofstream o(out, std::ios::binary);
    char buf[65536];
    zip_int64_t got = 0;
    while ((got = zip_fread(f, buf, sizeof buf)) > 0) o.write(buf, got);
    zip_fclose(f);
  }
  zip_close(z);
  return tmpl;
}

LoadedFmu::LoadedFmu(const std::string& fmu_path) {
  dir_ = extract_fmu(fmu_path);
  xml_ = read_text_file(dir_ + "/modelDescription.xml");
  const std::regex root("<fmiModelDescription[^>]*>");
  std::smatch m;
  if (!std::regex_search(xml_, m, root)) throw std::runtime_error("no fmiModelDescription element");
  guid_ = xml_attribute(m[0], "guid");
  const std::regex cs("<CoSimulation[^>]*>");
  if (!std::regex_search(xml_, m, cs)) throw std::runtime_error("no CoSimulation element");
  model_identifier_ = xml_attribute(m[0], "modelIdentifier");
  const std::regex var("<ScalarVariable([^>]*)>\\s*<(Real|Integer|Boolean|String)([^>]*)/>");
  for (auto it = std::sregex_iterator(xml_.begin(), xml_.end(), var); it != std::sregex_iterator(); ++it) {
    VarInfo v;
    const std::string a = (*it)[1];
    const std::string t = (*it)[3];
    v.name = xml_attribute(a, "name");
    v.vr = static_cast<unsigned>(std::stoul(xml_attribute(a, "valueReference")));
    v.causality = xml_attribute(a, "causality");
    v.variability = xml_attribute(a, "variability");
    v.initial = xml_attribute(a, "initial");
    v.type = (*it)[2];
    v.unit = xml_attribute(t, "unit");
    v.start = xml_attribute(t, "start");
    by_name_[v.name] = vars_.size();
    vars_.push_back(v);
  }
  handle_ = ::dlopen(so_path().c_str(), RTLD_NOW | RTLD_LOCAL);
  if (handle_ == nullptr) throw std::runtime_error(std::string("dlopen: ") + ::dlerror());
#define TWIN_FMI2_LOAD(name)                                                              \
  fn_.name = reinterpret_cast<decltype(fn_.name)>(::dlsym(handle_, #name));               \
  if (fn_.name == nullptr) throw std::runtime_error("the FMU does not export " #name);
  TWIN_FMI2_LOAD(fmi2GetTypesPlatform) TWIN_FMI2_LOAD(fmi2GetVersion) TWIN_FMI2_LOAD(fmi2SetDebugLogging)
  TWIN_FMI2_LOAD(fmi2Instantiate) TWIN_FMI2_LOAD(fmi2FreeInstance) TWIN_FMI2_LOAD(fmi2SetupExperiment)
  TWIN_FMI2_LOAD(fmi2EnterInitializationMode) TWIN_FMI2_LOAD(fmi2ExitInitializationMode) TWIN_FMI2_LOAD(fmi2Terminate)
  TWIN_FMI2_LOAD(fmi2Reset) TWIN_FMI2_LOAD(fmi2GetReal) TWIN_FMI2_LOAD(fmi2GetInteger) TWIN_FMI2_LOAD(fmi2GetBoolean)
  TWIN_FMI2_LOAD(fmi2GetString) TWIN_FMI2_LOAD(fmi2SetReal) TWIN_FMI2_LOAD(fmi2SetInteger) TWIN_FMI2_LOAD(fmi2SetBoolean)
  TWIN_FMI2_LOAD(fmi2SetString) TWIN_FMI2_LOAD(fmi2GetFMUstate) TWIN_FMI2_LOAD(fmi2SetFMUstate)
  TWIN_FMI2_LOAD(fmi2FreeFMUstate) TWIN_FMI2_LOAD(fmi2SerializedFMUstateSize) TWIN_FMI2_LOAD(fmi2SerializeFMUstate)
  TWIN_FMI2_LOAD(fmi2DeSerializeFMUstate) TWIN_FMI2_LOAD(fmi2GetDirectionalDerivative)
  TWIN_FMI2_LOAD(fmi2SetRealInputDerivatives) TWIN_FMI2_LOAD(fmi2GetRealOutputDerivatives) TWIN_FMI2_LOAD(fmi2DoStep)
  TWIN_FMI2_LOAD(fmi2CancelStep) TWIN_FMI2_LOAD(fmi2GetStatus) TWIN_FMI2_LOAD(fmi2GetRealStatus)
  TWIN_FMI2_LOAD(fmi2GetIntegerStatus) TWIN_FMI2_LOAD(fmi2GetBooleanStatus) TWIN_FMI2_LOAD(fmi2GetStringStatus)
#undef TWIN_FMI2_LOAD
  callbacks_.logger = &logger;
  callbacks_.componentEnvironment = &log_;
}

LoadedFmu::~LoadedFmu() {
  if (handle_ != nullptr) ::dlclose(handle_);
  std::error_code ec;
  std::filesystem::remove_all(dir_, ec);
}

std::string LoadedFmu::so_path() const { return dir_ + "/binaries/linux64/" + model_identifier_ + ".so"; }

const VarInfo& LoadedFmu::var(const std::string& name) const {
  const auto it = by_name_.find(name);
  if (it == by_name_.end()) throw std::runtime_error("no variable " + name);
  return vars_[it->second];
}

std::string LoadedFmu::default_experiment(const std::string& attribute) const {
  return default_experiment_attribute(xml_, attribute);
}

fmi2Component LoadedFmu::instantiate(const std::string& name, const char* guid, bool logging_on,
                                     const std::string& resources) {
  const std::string uri = resources.empty() ? resource_uri() : resources;
  return fn_.fmi2Instantiate(name.c_str(), fmi2CoSimulation, guid ? guid : guid_.c_str(), uri.c_str(), &callbacks_,
                             fmi2False, logging_on ? fmi2True : fmi2False);
}

}  // namespace twin::fmu_test
