// flarekit fit, flarekit fit-eval, flarekit bench fit.
#include "app/commands.h"

namespace flarekit::app {

void registerFitCommands(CLI::App& /*app*/) {}

}  // namespace flarekit::app
