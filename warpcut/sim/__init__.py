"""warpcut/sim"""
