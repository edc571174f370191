// What MachineTwin.so gives back when a master unloads it (dlclose).
//
// The static libstdc++ inside the FMU allocates its emergency pool for
// exceptions (72704 bytes, eh_alloc.cc) when the binary is loaded and never
// frees it: a master that loads and unloads the FMU repeatedly lost that
// much at every cycle (LeakSanitizer reported it in the sanitizer build of
// the test suite). libstdc++ provides __gnu_cxx::__freeres() to free it; the
// FMU calls it when it is unloaded, when no exception can be in flight in
// its code.
namespace __gnu_cxx {
void __freeres() noexcept;
}

namespace {

__attribute__((destructor)) void free_runtime_pools_on_unload() { __gnu_cxx::__freeres(); }

}  // namespace
