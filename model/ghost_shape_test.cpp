#include <gtest/gtest.h>

#include "model/ghost_shape.h"
