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

#include <gtest/gtest.h>

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

void expect_scenario_resources(const UnzippedFmu& fmu) {
  for (const char* r : {"model.json", "machine.yaml", "scenario.yaml"})
    EXPECT_TRUE(std::filesystem::exists(fmu.dir() + "/resources/" + r)) << r;
}

void expect_valid_model_description(const UnzippedFmu& fmu, const std::string& xsd) {
  std::string out;
  const int rc = validate_with_xsd(xsd, fmu.dir() + "/modelDescription.xml", out);
  EXPECT_EQ(rc, 0) << out;
}

void expect_only_the_c_runtime_needed(const std::string& so_path) {
  std::string out;
  ASSERT_EQ(run("ldd " + so_path, out), 0) << out;
  const std::regex allowed(R"(^\s*(linux-vdso\.so|libc\.so|libm\.so|libstdc\+\+\.so|libgcc_s\.so|/lib64/ld-linux))");
  std::istringstream lines(out);
  for (std::string line; std::getline(lines, line);)
    if (!line.empty()) {
      EXPECT_TRUE(std::regex_search(line, allowed)) << "the FMU needs: " << line;
    }
}

void serialize_state(const Fmi2Functions& f, fmi2Component c, fmi2FMUstate st, std::vector<fmi2Byte>& bytes) {
  std::size_t size = 0;
  ASSERT_EQ(f.fmi2SerializedFMUstateSize(c, st, &size), fmi2OK);
  bytes.resize(size);
  ASSERT_EQ(f.fmi2SerializeFMUstate(c, st, bytes.data(), size), fmi2OK);
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

UnzippedFmu::UnzippedFmu(const std::string& fmu_path)
    : dir_(extract_fmu(fmu_path)), xml_(read_text_file(dir_ + "/modelDescription.xml")) {}

UnzippedFmu::~UnzippedFmu() {
  if (handle_ != nullptr) ::dlclose(handle_);
  std::error_code ec;
  std::filesystem::remove_all(dir_, ec);
}

std::string UnzippedFmu::element(const std::string& tag) const {
  std::smatch m;
  if (!std::regex_search(xml_, m, std::regex("<" + tag + "[^>]*>"))) throw std::runtime_error("no " + tag + " element");
  return m[0];
}

void UnzippedFmu::add_variable(const VarInfo& v) {
  by_name_[v.name] = vars_.size();
  vars_.push_back(v);
}

void UnzippedFmu::load_binary(const std::string& so_path) {
  handle_ = ::dlopen(so_path.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (handle_ == nullptr) throw std::runtime_error(std::string("dlopen: ") + ::dlerror());
}

void* UnzippedFmu::symbol(const std::string& name) const {
  void* f = ::dlsym(handle_, name.c_str());
  if (f == nullptr) throw std::runtime_error("the FMU does not export " + name);
  return f;
}

const VarInfo& UnzippedFmu::var(const std::string& name) const {
  const auto it = by_name_.find(name);
  if (it == by_name_.end()) throw std::runtime_error("no variable " + name);
  return vars_[it->second];
}

std::string UnzippedFmu::default_experiment(const std::string& attribute) const {
  return default_experiment_attribute(xml_, attribute);
}

LoadedFmu::LoadedFmu(const std::string& fmu_path) : UnzippedFmu(fmu_path) {
  guid_ = xml_attribute(element("fmiModelDescription"), "guid");
  model_identifier_ = xml_attribute(element("CoSimulation"), "modelIdentifier");
  const std::regex var("<ScalarVariable([^>]*)>\\s*<(Real|Integer|Boolean|String)([^>]*)/>");
  for (auto it = std::sregex_iterator(xml().begin(), xml().end(), var); it != std::sregex_iterator(); ++it) {
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
    add_variable(v);
  }
  load_binary(so_path());
#define TWIN_FMI2_LOAD(name) fn_.name = reinterpret_cast<decltype(fn_.name)>(symbol(#name));
  TWIN_FMI2_FUNCTIONS(TWIN_FMI2_LOAD)
#undef TWIN_FMI2_LOAD
  callbacks_.logger = &logger;
  callbacks_.componentEnvironment = &log_;
}

std::string LoadedFmu::so_path() const { return dir() + "/binaries/linux64/" + model_identifier_ + ".so"; }

fmi2Component LoadedFmu::instantiate(const std::string& name, const char* guid, bool logging_on,
                                     const std::string& resources) {
  const std::string uri = resources.empty() ? resource_uri() : resources;
  return fn_.fmi2Instantiate(name.c_str(), fmi2CoSimulation, guid ? guid : guid_.c_str(), uri.c_str(), &callbacks_,
                             fmi2False, logging_on ? fmi2True : fmi2False);
}

}  // namespace twin::fmu_test
