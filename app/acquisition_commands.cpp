// flarekit rig-check, merge, capture, bench merge
#include "app/commands.h"

namespace flarekit::app {

void registerAcquisitionCommands(CLI::App& app) { (void)app; }

}  // namespace flarekit::app
