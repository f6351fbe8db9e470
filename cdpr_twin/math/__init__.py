"""Pure mathematics of cable robots: SE(3), geometry, kinematics, statics, catenary.

numpy and scipy only: no MuJoCo, no other layer of the package.
"""
