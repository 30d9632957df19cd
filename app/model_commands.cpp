// flarekit render, flarekit model-info, flarekit bench model.
#include "app/commands.h"

namespace flarekit::app {

void registerModelCommands(CLI::App& /*app*/) {}

}  // namespace flarekit::app
