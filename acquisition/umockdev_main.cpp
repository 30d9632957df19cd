// main() of the umockdev test binary: the tests need libumockdev-preload, so the binary re-runs
// itself under umockdev-wrapper when it was started without it.
#include <gtest/gtest.h>
#include <umockdev.h>
#include <unistd.h>

#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

int main(int argc, char** argv) {
  const char* preload = std::getenv("LD_PRELOAD");
  const bool preloaded = preload && std::strstr(preload, "umockdev");
  bool listing = false;  // test discovery needs no devices
  for (int i = 1; i < argc; ++i) listing = listing || std::strcmp(argv[i], "--gtest_list_tests") == 0;
  if (!preloaded && !listing && !std::getenv("FLAREKIT_UMOCKDEV_REEXEC")) {
    setenv("FLAREKIT_UMOCKDEV_REEXEC", "1", 1);
    // Sanitizer builds: the preload library comes before the ASan runtime in the library list.
    std::string asan = std::getenv("ASAN_OPTIONS") ? std::getenv("ASAN_OPTIONS") : "";
    if (asan.find("verify_asan_link_order") == std::string::npos) {
      asan += std::string(asan.empty() ? "" : ":") + "verify_asan_link_order=0";
      setenv("ASAN_OPTIONS", asan.c_str(), 1);
    }
    std::vector<char*> args;
    args.push_back(const_cast<char*>("umockdev-wrapper"));
    for (int i = 0; i < argc; ++i) args.push_back(argv[i]);
    args.push_back(nullptr);
    execvp("umockdev-wrapper", args.data());
    std::fprintf(stderr, "cannot run umockdev-wrapper (Debian package umockdev)\n");
    return 1;
  }
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
