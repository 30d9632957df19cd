#include "acquisition/device.h"

#include <algorithm>
#include <cctype>
#include <string>

namespace flarekit::acquisition {

std::string_view cfaName(Cfa cfa) {
  switch (cfa) {
    case Cfa::kMono: return "mono";
    case Cfa::kRGGB: return "RGGB";
    case Cfa::kBGGR: return "BGGR";
    case Cfa::kGRBG: return "GRBG";
    case Cfa::kGBRG: return "GBRG";
  }
  return "mono";
}

bool parseCfa(std::string_view text, Cfa* cfa) {
  std::string upper(text);
  std::transform(upper.begin(), upper.end(), upper.begin(),
                 [](unsigned char c) { return static_cast<char>(std::toupper(c)); });
  for (Cfa c : {Cfa::kMono, Cfa::kRGGB, Cfa::kBGGR, Cfa::kGRBG, Cfa::kGBRG}) {
    std::string name(cfaName(c));
    std::transform(name.begin(), name.end(), name.begin(),
                   [](unsigned char ch) { return static_cast<char>(std::toupper(ch)); });
    if (name == upper) {
      *cfa = c;
      return true;
    }
  }
  return false;
}

int cfaColor(Cfa cfa, int row, int col) {
  if (cfa == Cfa::kMono) return 1;
  const char* pattern = "RGGB";
  switch (cfa) {
    case Cfa::kRGGB: pattern = "RGGB"; break;
    case Cfa::kBGGR: pattern = "BGGR"; break;
    case Cfa::kGRBG: pattern = "GRBG"; break;
    case Cfa::kGBRG: pattern = "GBRG"; break;
    case Cfa::kMono: break;
  }
  const char c = pattern[(row & 1) * 2 + (col & 1)];
  return c == 'R' ? 0 : (c == 'G' ? 1 : 2);
}

}  // namespace flarekit::acquisition
