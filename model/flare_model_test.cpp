#include <gtest/gtest.h>

#include "model/flare_model.h"
