"""Constants of another module, used by test_lang_constants.py as mymod.N / mymod.SCALE."""
N = 12
SCALE = 0.125
