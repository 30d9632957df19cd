#include <gtest/gtest.h>

#include "model/model_renderer.h"
