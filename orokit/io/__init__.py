"""orokit.io"""
